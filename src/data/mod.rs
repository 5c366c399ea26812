//! STAND-IN (render branch only) for the lead's data layer: masks, RLE, polygons, COCO.
//! mask/rle/polygon are copies of the lead's work-in-progress files; coco.rs is a tiny
//! subset. All four are replaced by the lead's versions at merge.
pub mod coco;
pub mod mask;
pub mod polygon;
pub mod rle;
