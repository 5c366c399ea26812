//! `chicktrain export --format safetensors`: a checkpoint's EMA weights as the state dict
//! of the Python model it mirrors, so that `model.load_state_dict(safetensors.torch.load_file(PATH))`
//! takes it. YOLO: ultralytics' keys (BatchNorm statistics, `num_batches_tracked` and the
//! fixed DFL conv included); the `__metadata__` says how to build that model in
//! ultralytics (scale row, nc, nm, names). Mask R-CNN: torchvision's
//! `maskrcnn_resnet50_fpn` (v1) keys with the background class first
//! ([`torchvision_state_dict`]); the metadata gives the sizes and, where one exists, the
//! torchvision builder that makes the same model.

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{bail, Result};
use burn::tensor::Device;

use crate::infer::checkpoint::Checkpoint;
use crate::infer::detector::{Detector, DetectorConfig};
use crate::model::maskrcnn::anchors::AnchorConfig;
use crate::model::maskrcnn::torchvision::torchvision_state_dict;
use crate::model::maskrcnn::MaskRcnnConfig;
use crate::model::yolo::scale::Scaler;
use crate::model::yolo::ultralytics::ultralytics_state_dict;
use crate::weights::safetensors;

pub fn export(ckpt: &Checkpoint, from: &Path, out: &Path) -> Result<String> {
    let cfg = match &ckpt.header.model {
        DetectorConfig::Yolo(cfg) => cfg,
        DetectorConfig::Maskrcnn(cfg) => return export_maskrcnn(ckpt, cfg, from, out),
        DetectorConfig::Mask2former(_) => bail!(
            "{}: safetensors export of Mask2Former is not implemented (YOLO-seg and Mask R-CNN export)",
            from.display()
        ),
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

/// The torchvision call that builds a model of `cfg`'s sizes, if one does: the paper
/// preset at full width is `resnet_fpn_backbone` + `MaskRCNN` with torchvision's
/// defaults (`maskrcnn_resnet50_fpn` itself for ResNet-50).
pub fn torchvision_builder(cfg: &MaskRcnnConfig) -> Option<String> {
    let paper = MaskRcnnConfig::paper(cfg.depth, cfg.num_classes);
    let same = cfg.width_mult == 1.0
        && cfg.fpn_channels == paper.fpn_channels
        && cfg.roi.fc_dim == paper.roi.fc_dim
        && cfg.roi.num_fc == paper.roi.num_fc
        && cfg.roi.pool_size == 7
        && cfg.mask.conv_dim == paper.mask.conv_dim
        && cfg.mask.num_conv == paper.mask.num_conv
        && cfg.mask.pool_size == 14
        && cfg.anchors == AnchorConfig::paper();
    let k = cfg.num_classes + 1;
    same.then(|| match cfg.depth {
        50 => format!(
            "torchvision.models.detection.maskrcnn_resnet50_fpn(weights=None, weights_backbone=None, num_classes={k})"
        ),
        d => format!(
            "torchvision.models.detection.MaskRCNN(torchvision.models.detection.backbone_utils.resnet_fpn_backbone(backbone_name=\"resnet{d}\", weights=None, trainable_layers=5), num_classes={k})"
        ),
    })
}

fn export_maskrcnn(
    ckpt: &Checkpoint,
    cfg: &MaskRcnnConfig,
    from: &Path,
    out: &Path,
) -> Result<String> {
    let Detector::MaskRcnn(model) = ckpt.model("ema", &Device::flex())? else {
        bail!("{}: the weights are not a Mask R-CNN", from.display());
    };
    let sd =
        torchvision_state_dict(&model).map_err(|e| anyhow::anyhow!("{}: {e}", from.display()))?;
    // torchvision's class 0 is the background.
    let mut names: BTreeMap<String, &str> = BTreeMap::from([("0".to_string(), "__background__")]);
    for (i, n) in ckpt.header.class_names.iter().enumerate() {
        names.insert((i + 1).to_string(), n);
    }
    let builder = torchvision_builder(cfg);
    let sizes = serde_json::json!({
        "depth": cfg.depth,
        "width_mult": cfg.width_mult,
        "fpn_channels": cfg.fpn_channels,
        "box_fc_dim": cfg.roi.fc_dim,
        "box_num_fc": cfg.roi.num_fc,
        "box_pool": cfg.roi.pool_size,
        "mask_conv_dim": cfg.mask.conv_dim,
        "mask_num_conv": cfg.mask.num_conv,
        "mask_pool": cfg.mask.pool_size,
        "anchor_sizes": cfg.anchors.sizes,
        "anchor_ratios": cfg.anchors.ratios,
    });
    let meta = BTreeMap::from([
        ("format".to_string(), "pt".to_string()),
        (
            "producer".into(),
            format!("chicktrain {}", env!("CARGO_PKG_VERSION")),
        ),
        (
            "architecture".into(),
            "torchvision maskrcnn_resnet_fpn v1".into(),
        ),
        (
            "torchvision_builder".into(),
            builder.clone().unwrap_or_else(|| "none".into()),
        ),
        ("chicktrain_maskrcnn".into(), sizes.to_string()),
        ("num_classes".into(), (cfg.num_classes + 1).to_string()),
        ("names".into(), serde_json::to_string(&names)?),
        ("epoch".into(), ckpt.header.epoch.to_string()),
    ]);
    safetensors::write(out, &sd, &meta)?;
    Ok(format!(
        "wrote {} ({} tensors, torchvision maskrcnn_resnet_fpn names, {} classes with background first); {}",
        out.display(),
        sd.len(),
        cfg.num_classes + 1,
        match builder {
            Some(b) => format!("loads into {b}"),
            None => format!(
                "no torchvision builder makes these sizes (ResNet-{} ×{} width, {}-wide FPN, {}-wide box FCs, {}-wide mask convs): build torchvision's classes at them (bench/maskrcnn_export_check.py does)",
                cfg.depth, cfg.width_mult, cfg.fpn_channels, cfg.roi.fc_dim, cfg.mask.conv_dim
            ),
        }
    ))
}
