//! Data: COCO files and masks (RLE, polygons), LabelMe import, YOLO export, splits, and
//! the training side (feature `train`): sources (`dataset`), augmentation (`augment`),
//! batching (`batch`).

#[cfg(feature = "train")]
pub mod augment;
#[cfg(feature = "train")]
pub mod batch;
pub mod coco;
#[cfg(feature = "train")]
pub mod dataset;
pub mod image_file;
pub mod labelme;
pub mod letterbox;
pub mod mask;
pub mod polygon;
pub mod rle;
pub mod split;
pub mod yolo_export;
