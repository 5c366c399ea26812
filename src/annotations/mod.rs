//! The annotation foundation every stage stands on: COCO files and masks (RLE and
//! polygons byte-identical to pycocotools), COCO files per split, LabelMe import, YOLO-seg
//! datasets in and out, image files, the train/val/test split, and [`targets`]: the
//! host-side ground truth every model family trains on.
//!
//! It imports nothing from the rest of the crate but [`crate::util`], so the renderer
//! (which writes COCO) and the evaluator (which reads it) sit above it, and the training
//! loader (`data/`) above the renderer.

pub mod coco;
pub mod coco_splits;
pub mod image_file;
pub mod labelme;
pub mod mask;
pub mod polygon;
pub mod rle;
pub mod split;
pub mod targets;
pub mod yolo;
pub mod yolo_export;
pub mod yolo_yaml;
