//! Mask R-CNN's export formats (its `Family::ONNX` and `Family::SAFETENSORS`): three ONNX
//! graphs (backbone + FPN + RPN head, box head, mask head; [`super::onnx`] builds them),
//! optionally with reference inputs and outputs of all three; the safetensors state dict
//! under torchvision's key names ([`super::torchvision`]).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use burn::tensor::{Device, Tensor, TensorData};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::model::family::ExportRequest;
use crate::model::onnx::graph::encode;
use crate::model::onnx::reference::{reference_file, reference_path, REFERENCE_SEED};
use crate::util::tensor::to_host;
use crate::util::write_atomic;
use crate::weights::safetensors;

use super::anchors::AnchorConfig;
use super::onnx::{export_maskrcnn, BOX_INPUT, BOX_OUTPUTS, LEVELS, MASK_INPUT, MASK_OUTPUT};
use super::torchvision::torchvision_state_dict;
use super::{MaskRcnn, MaskRcnnConfig, STRIDES};

/// Paths of the RoI head graphs beside an exported Mask R-CNN `best.onnx`.
pub fn roi_head_paths(onnx: &Path) -> [PathBuf; 2] {
    [
        onnx.with_extension("box_head.onnx"),
        onnx.with_extension("mask_head.onnx"),
    ]
}

/// RoIs in the reference inputs of the RoI head graphs.
const REFERENCE_ROIS: usize = 4;

/// `export --format onnx`: three graphs ([`super::onnx`]), written all or none.
pub fn onnx(m: &MaskRcnn, cfg: &MaskRcnnConfig, r: &ExportRequest) -> Result<String> {
    let size = cfg.input_size;
    let [box_path, mask_path] = roi_head_paths(r.out);
    let file = |p: &Path| {
        p.file_name()
            .map(|f| f.to_string_lossy().into_owned())
            .unwrap_or_default()
    };
    let meta = vec![
        ("chicktrain_model".to_string(), "maskrcnn".to_string()),
        (
            "chicktrain_maskrcnn".into(),
            serde_json::to_string(&m.config)?,
        ),
        ("names".into(), serde_json::to_string(r.class_names)?),
        (
            "chicktrain_category_ids".into(),
            serde_json::to_string(r.category_ids)?,
        ),
        ("strides".into(), serde_json::to_string(&STRIDES)?),
        ("box_head".into(), file(&box_path)),
        ("mask_head".into(), file(&mask_path)),
    ];
    let g = export_maskrcnn(m, [size, size], (!r.dynamic).then_some(r.batch), &meta)
        .with_context(|| format!("exporting {}", r.checkpoint.display()))?;
    let files = [
        (r.out.to_path_buf(), encode(&g.backbone)),
        (box_path.clone(), encode(&g.box_head)),
        (mask_path.clone(), encode(&g.mask_head)),
    ];
    for (k, (p, bytes)) in files.iter().enumerate() {
        if let Err(e) = write_atomic(p, bytes) {
            for (done, _) in &files[..k] {
                let _ = std::fs::remove_file(done);
            }
            return Err(e);
        }
    }
    let c = m.fpn.channels;
    let nc = m.num_classes();
    let (pb, pm) = (m.config.roi.pool_size, m.config.mask.pool_size);
    let mut msg = format!(
        "{} → {} ({:.1} MB, opset 17: images [{}, 3, {size}, {size}] → p2…p6, rpn_objectness.pN, rpn_deltas.pN), \
         {} (box_features [rois, {c}, {pb}, {pb}] → class_logits [rois, {}], box_deltas [rois, {}]), \
         {} (mask_features [rois, {c}, {pm}, {pm}] → mask_logits [rois, {}, {}, {}]); \
         anchors, proposals, RoIAlign, box decoding, NMS and mask pasting stay outside the graphs",
        r.checkpoint.display(),
        r.out.display(),
        files[0].1.len() as f64 / 1e6,
        if r.dynamic { "batch".to_string() } else { r.batch.to_string() },
        box_path.display(),
        nc + 1,
        m.box_head.bbox_pred.weight.dims()[1],
        mask_path.display(),
        m.mask_head.predictor.weight.dims()[0],
        2 * pm,
        2 * pm,
    );
    if r.reference {
        msg.push_str(&reference(m, r, size)?);
    }
    Ok(msg)
}

/// The reference file of the three graphs: seeded inputs (images, and RoI features for
/// the heads) and chicktrain's outputs for them; the message line saying where it is.
fn reference(m: &MaskRcnn, r: &ExportRequest, size: usize) -> Result<String> {
    let c = m.fpn.channels;
    let (pb, pm) = (m.config.roi.pool_size, m.config.mask.pool_size);
    let dev = Device::flex();
    let b = r.batch;
    let mut rng = ChaCha8Rng::seed_from_u64(REFERENCE_SEED);
    let mut uniform = |n: usize| -> Vec<f32> { (0..n).map(|_| rng.random::<f32>()).collect() };
    let x = uniform(b * 3 * size * size);
    let feats = m.features(Tensor::<4>::from_data(
        TensorData::new(x.clone(), [b, 3, size, size]),
        &dev,
    ));
    let maps = m.rpn.forward_levels(&feats);
    let mut named: Vec<(String, Vec<usize>, Vec<f32>)> =
        vec![("images".into(), vec![b, 3, size, size], x)];
    let mut host4 = |name: String, t: Tensor<4>| {
        let s = t.dims().to_vec();
        named.push((name, s, to_host(t)));
    };
    for (l, f) in feats.into_iter().enumerate() {
        host4(LEVELS[l].to_string(), f);
    }
    let (obj, del): (Vec<_>, Vec<_>) = maps.into_iter().unzip();
    for (l, t) in obj.into_iter().enumerate() {
        host4(format!("rpn_objectness.{}", LEVELS[l]), t);
    }
    for (l, t) in del.into_iter().enumerate() {
        host4(format!("rpn_deltas.{}", LEVELS[l]), t);
    }
    let n = REFERENCE_ROIS;
    let bx = uniform(n * c * pb * pb);
    let mx = uniform(n * c * pm * pm);
    let (cls, deltas) = m.box_head.forward(Tensor::from_data(
        TensorData::new(bx.clone(), [n, c, pb, pb]),
        &dev,
    ));
    let logits = m.mask_head.forward(Tensor::from_data(
        TensorData::new(mx.clone(), [n, c, pm, pm]),
        &dev,
    ));
    named.push((BOX_INPUT.into(), vec![n, c, pb, pb], bx));
    named.push((BOX_OUTPUTS[0].into(), cls.dims().to_vec(), to_host(cls)));
    named.push((
        BOX_OUTPUTS[1].into(),
        deltas.dims().to_vec(),
        to_host(deltas),
    ));
    named.push((MASK_INPUT.into(), vec![n, c, pm, pm], mx));
    named.push((MASK_OUTPUT.into(), logits.dims().to_vec(), to_host(logits)));
    let path = reference_path(r.out);
    write_atomic(&path, &reference_file(named)?)?;
    Ok(format!(
        "\nreference inputs (seed {REFERENCE_SEED}) and chicktrain's outputs of all three graphs: {}",
        path.display()
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

/// `export --format safetensors`: torchvision's `maskrcnn_resnet50_fpn` (v1) keys with the
/// background class first; the metadata gives the sizes and, where one exists, the
/// torchvision builder that makes the same model.
pub fn safetensors(m: &MaskRcnn, cfg: &MaskRcnnConfig, r: &ExportRequest) -> Result<String> {
    let sd = torchvision_state_dict(m)
        .map_err(|e| anyhow::anyhow!("{}: {e}", r.checkpoint.display()))?;
    // torchvision's class 0 is the background.
    let mut names: BTreeMap<String, &str> = BTreeMap::from([("0".to_string(), "__background__")]);
    for (i, n) in r.class_names.iter().enumerate() {
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
        ("epoch".into(), r.epoch.to_string()),
    ]);
    safetensors::write(r.out, &sd, &meta)?;
    Ok(format!(
        "wrote {} ({} tensors, torchvision maskrcnn_resnet_fpn names, {} classes with background first); {}",
        r.out.display(),
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
