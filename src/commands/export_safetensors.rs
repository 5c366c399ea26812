//! `chicktrain export --format safetensors`: a YOLO checkpoint's EMA weights as an ultralytics
//! state dict (BatchNorm statistics, `num_batches_tracked` and the fixed DFL conv included),
//! so that `model.load_state_dict(safetensors.torch.load_file(PATH))` takes it. The
//! `__metadata__` says how to build that model in ultralytics (scale row, nc, nm, names).

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{bail, Result};
use burn::tensor::Device;

use crate::model::yolo::scale::Scaler;
use crate::model::yolo::ultralytics::ultralytics_state_dict;
use crate::train::checkpoint::Checkpoint;
use crate::train::detector::{Detector, DetectorConfig};
use crate::util::safetensors;

pub fn export(ckpt: &Checkpoint, from: &Path, out: &Path) -> Result<String> {
    let DetectorConfig::Yolo(cfg) = &ckpt.header.model else {
        bail!(
            "{}: safetensors export writes YOLO checkpoints (ultralytics' key names); \
             Mask R-CNN export under torchvision's key names is not implemented yet",
            from.display()
        );
    };
    let Detector::Yolo(model) = ckpt.model("ema", &Device::flex())? else {
        bail!("{}: the weights are not a YOLO model", from.display());
    };
    let sd = ultralytics_state_dict(&model, cfg)?;
    let sc = Scaler::new(cfg.scale, cfg.width_mult);
    let names: BTreeMap<String, &String> = ckpt
        .header
        .class_names
        .iter()
        .enumerate()
        .map(|(i, n)| (i.to_string(), n))
        .collect();
    let meta = BTreeMap::from([
        ("format".to_string(), "pt".to_string()),
        (
            "producer".into(),
            format!("chicktrain {}", env!("CARGO_PKG_VERSION")),
        ),
        ("architecture".into(), "yolo11-seg.yaml".into()),
        (
            "ultralytics_scale".into(),
            serde_json::json!([sc.depth, sc.width, sc.max_channels]).to_string(),
        ),
        ("nc".into(), cfg.num_classes.to_string()),
        ("nm".into(), cfg.num_masks.to_string()),
        ("imgsz".into(), cfg.input_size.to_string()),
        ("names".into(), serde_json::to_string(&names)?),
        ("epoch".into(), ckpt.header.epoch.to_string()),
    ]);
    safetensors::write(out, &sd, &meta)?;
    Ok(format!(
        "wrote {} ({} tensors, ultralytics yolo11-seg names; scale [{}, {}, {}], nc {}, nm {})",
        out.display(),
        sd.len(),
        sc.depth,
        sc.width,
        sc.max_channels,
        cfg.num_classes,
        cfg.num_masks
    ))
}
