//! Data: COCO files and masks (RLE, polygons), LabelMe import, YOLO export, splits.

pub mod coco;
pub mod labelme;
pub mod mask;
pub mod polygon;
pub mod rle;
pub mod split;
pub mod yolo_export;
