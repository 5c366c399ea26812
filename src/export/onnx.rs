//! `export --format onnx`: a checkpoint's YOLO-seg as an ONNX file in ultralytics'
//! layout, or a Mask R-CNN as three graphs (backbone + FPN + RPN head, box head, mask
//! head; `model::maskrcnn::onnx`), optionally with a reference input and chicktrain's own
//! outputs for it (a safetensors file), which `bench/onnx_check.py` and
//! `bench/maskrcnn_export_check.py` compare against ONNX Runtime. Running such a file is
//! `infer::onnx` (`predict --onnx`).

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use burn::tensor::{Device, Tensor, TensorData};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::infer::checkpoint::Checkpoint;
use crate::infer::detector::Detector;
use crate::model::maskrcnn::onnx::{
    export_maskrcnn, BOX_INPUT, BOX_OUTPUTS, LEVELS, MASK_INPUT, MASK_OUTPUT,
};
use crate::model::maskrcnn::{MaskRcnn, STRIDES};
use crate::model::onnx::graph::encode;
use crate::model::yolo::onnx::{export_yolo, ultralytics_output0, OnnxExportOptions};
use crate::util::tensor::to_host;
use crate::util::write_atomic;
use crate::weights::host::HostTensor;
use crate::weights::safetensors::to_bytes;

/// Options of `export --format onnx`.
#[derive(Debug, Clone)]
pub struct OnnxExport {
    pub checkpoint: PathBuf,
    pub out: PathBuf,
    pub batch: usize,
    pub dynamic: bool,
    /// Also write `<out>.reference.safetensors`: a seeded input and chicktrain's outputs.
    pub reference: bool,
}

/// Seed of the reference input (uniform [0, 1] pixels).
pub const REFERENCE_SEED: u64 = 0;

/// Path of the reference file next to an exported `model.onnx`.
pub fn reference_path(onnx: &Path) -> PathBuf {
    onnx.with_extension("reference.safetensors")
}

/// `chicktrain export --checkpoint X.bpk --format onnx [--out Y.onnx]`.
pub fn export_onnx(r: &OnnxExport) -> Result<String> {
    let ck = Checkpoint::load(&r.checkpoint)?;
    let dev = Device::flex();
    let model = ck
        .model("ema", &dev)
        .with_context(|| format!("in checkpoint {}", r.checkpoint.display()))?;
    let yolo = match &model {
        Detector::Yolo(m) => m,
        Detector::MaskRcnn(m) => return export_maskrcnn_onnx(r, &ck, m),
        Detector::Mask2Former(_) => bail!(
            "{}: ONNX export of Mask2Former is not implemented (YOLO-seg and Mask R-CNN export)",
            r.checkpoint.display()
        ),
    };
    let size = ck.header.model.input_size();
    let opts = OnnxExportOptions {
        batch: r.batch,
        dynamic: r.dynamic,
        names: ck.header.class_names.clone(),
        category_ids: ck.header.category_ids.clone(),
    };
    let proto = export_yolo(yolo, [size, size], &opts)
        .with_context(|| format!("exporting {}", r.checkpoint.display()))?;
    let bytes = encode(&proto);
    write_atomic(&r.out, &bytes)?;
    let mut msg = format!(
        "{} → {} ({:.1} MB, opset 17, input images [{}, 3, {size}, {size}], outputs output0 [B, {}, A] and output1 (prototypes))",
        r.checkpoint.display(),
        r.out.display(),
        bytes.len() as f64 / 1e6,
        if r.dynamic { "batch".to_string() } else { r.batch.to_string() },
        4 + yolo.num_classes() + yolo.head.num_masks,
    );
    if r.reference {
        let b = r.batch;
        let mut rng = ChaCha8Rng::seed_from_u64(REFERENCE_SEED);
        let x: Vec<f32> = (0..b * 3 * size * size)
            .map(|_| rng.random::<f32>())
            .collect();
        let out = yolo.forward(Tensor::<4>::from_data(
            TensorData::new(x.clone(), [b, 3, size, size]),
            &dev,
        ));
        let (y0, s0) = ultralytics_output0(&out);
        let s1 = out.proto.dims();
        let y1 = to_host(out.proto);
        let path = reference_path(&r.out);
        let file = reference_file(vec![
            ("images".into(), vec![b, 3, size, size], x),
            ("output0".into(), s0.to_vec(), y0),
            ("output1".into(), s1.to_vec(), y1),
        ])?;
        write_atomic(&path, &file)?;
        msg.push_str(&format!(
            "\nreference input (seed {REFERENCE_SEED}) and chicktrain's outputs: {}",
            path.display()
        ));
    }
    Ok(msg)
}

/// Paths of the RoI head graphs beside an exported Mask R-CNN `best.onnx`.
pub fn roi_head_paths(onnx: &Path) -> [PathBuf; 2] {
    [
        onnx.with_extension("box_head.onnx"),
        onnx.with_extension("mask_head.onnx"),
    ]
}

/// RoIs in the reference inputs of the RoI head graphs.
const REFERENCE_ROIS: usize = 4;

/// Mask R-CNN: three graphs ([`crate::model::maskrcnn::onnx`]), written all or none.
fn export_maskrcnn_onnx(r: &OnnxExport, ck: &Checkpoint, m: &MaskRcnn) -> Result<String> {
    let size = ck.header.model.input_size();
    let [box_path, mask_path] = roi_head_paths(&r.out);
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
        (
            "names".into(),
            serde_json::to_string(&ck.header.class_names)?,
        ),
        (
            "chicktrain_category_ids".into(),
            serde_json::to_string(&ck.header.category_ids)?,
        ),
        ("strides".into(), serde_json::to_string(&STRIDES)?),
        ("box_head".into(), file(&box_path)),
        ("mask_head".into(), file(&mask_path)),
    ];
    let g = export_maskrcnn(m, [size, size], (!r.dynamic).then_some(r.batch), &meta)
        .with_context(|| format!("exporting {}", r.checkpoint.display()))?;
    let files = [
        (r.out.clone(), encode(&g.backbone)),
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
        let path = reference_path(&r.out);
        write_atomic(&path, &reference_file(named)?)?;
        msg.push_str(&format!(
            "\nreference inputs (seed {REFERENCE_SEED}) and chicktrain's outputs of all three graphs: {}",
            path.display()
        ));
    }
    Ok(msg)
}

/// The reference file: float32 tensors in the given order, no metadata — the one format
/// both Rust and NumPy read without a pickle.
fn reference_file(named: Vec<(String, Vec<usize>, Vec<f32>)>) -> Result<Vec<u8>> {
    let tensors: Vec<(String, HostTensor)> = named
        .into_iter()
        .map(|(k, shape, v)| (k, HostTensor::f32(shape, v)))
        .collect();
    to_bytes(&tensors, &Default::default())
}
