//! Data: COCO files and masks (RLE, polygons), LabelMe import, YOLO export, splits, and
//! the training side: sources ([`dataset`]), augmentation ([`augment`]), batching ([`batch`]).

pub mod augment;
pub mod batch;
pub mod coco;
pub mod dataset;
pub mod labelme;
pub mod letterbox;
pub mod mask;
pub mod polygon;
pub mod rle;
pub mod split;
pub mod yolo_export;
