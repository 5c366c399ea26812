//! The ONNX side of `export` and `predict --onnx`: a checkpoint's YOLO-seg as an ONNX
//! file in ultralytics' layout, or a Mask R-CNN as three graphs (backbone + FPN + RPN
//! head, box head, mask head; `model::maskrcnn::onnx`), optionally with a reference
//! input and chicktrain's own outputs for it, which `bench/onnx_check.py` and
//! `bench/maskrcnn_export_check.py` compare against ONNX Runtime; and
//! predictions from such a file (or a Mask R-CNN export's three graphs) through tract
//! with the same postprocess and outputs as `predict --checkpoint`.

use std::path::{Path, PathBuf};

use anyhow::{bail, ensure, Context, Result};
use burn::tensor::{Device, Tensor, TensorData};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::predict::PredictOptions;
use super::train::{predict_images, PredictClasses};
use crate::bench::engines::bench_engines;
use crate::bench::models::parse_sizes;
use crate::bench::variant::Variant;
use crate::model::detection::nms_detections;
use crate::model::maskrcnn::onnx::{
    export_maskrcnn, OnnxMaskRcnn, BOX_INPUT, BOX_OUTPUTS, LEVELS, MASK_INPUT, MASK_OUTPUT,
};
use crate::model::maskrcnn::{infer, MaskRcnn, MaskRcnnConfig, STRIDES};
use crate::model::onnx::engine::{set_threads, TractEngine};
use crate::model::onnx::graph::encode;
use crate::model::yolo::onnx::{export_yolo, ultralytics_output0, OnnxExportOptions};
use crate::model::yolo::postprocess::postprocess_layout;
use crate::train::checkpoint::Checkpoint;
use crate::train::detector::Detector;
use crate::util::tensor::to_host;
use crate::util::write_atomic;

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
        let file = safetensors_f32(&[
            ("images", &[b, 3, size, size], &x),
            ("output0", &s0, &y0),
            ("output1", &s1, &y1),
        ]);
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
        let refs: Vec<(&str, &[usize], &[f32])> = named
            .iter()
            .map(|(k, s, v)| (k.as_str(), s.as_slice(), v.as_slice()))
            .collect();
        let path = reference_path(&r.out);
        write_atomic(&path, &safetensors_f32(&refs))?;
        msg.push_str(&format!(
            "\nreference inputs (seed {REFERENCE_SEED}) and chicktrain's outputs of all three graphs: {}",
            path.display()
        ));
    }
    Ok(msg)
}

/// A safetensors file of float32 tensors (8-byte little-endian header length, JSON
/// header, raw data): the one format both Rust and NumPy read without a pickle.
fn safetensors_f32(tensors: &[(&str, &[usize], &[f32])]) -> Vec<u8> {
    let mut header = serde_json::Map::new();
    let mut off = 0usize;
    for (name, shape, data) in tensors {
        assert_eq!(shape.iter().product::<usize>(), data.len(), "{name}");
        let end = off + 4 * data.len();
        header.insert(
            name.to_string(),
            serde_json::json!({"dtype": "F32", "shape": shape, "data_offsets": [off, end]}),
        );
        off = end;
    }
    let mut h = serde_json::to_vec(&header).expect("a JSON map serialises");
    while h.len() % 8 != 0 {
        h.push(b' ');
    }
    let mut out = Vec::with_capacity(8 + h.len() + off);
    out.extend_from_slice(&(h.len() as u64).to_le_bytes());
    out.extend_from_slice(&h);
    for (_, _, data) in tensors {
        for v in *data {
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
    out
}

/// What `predict --onnx` needs to know about an exported file, read from it.
struct OnnxModelInfo {
    size: usize,
    num_classes: usize,
    classes: PredictClasses,
}

fn model_info(eng: &TractEngine) -> Result<OnnxModelInfo> {
    let p = eng.path.display();
    let s = &eng.input_shape;
    ensure!(
        s.len() == 4 && s[1] == Some(3),
        "{p}: input must be [B, 3, H, W], the file declares {s:?}"
    );
    let (h, w) = match (s[2], s[3]) {
        (Some(h), Some(w)) => (h, w),
        _ => bail!("{p}: input height and width must be fixed (the file declares {s:?})"),
    };
    ensure!(
        h == w,
        "{p}: predict letterboxes to a square input; this file's is {h}×{w}"
    );
    let g = eng.proto.graph.as_ref().expect("checked at load");
    ensure!(
        g.output.len() == 2,
        "{p}: expected two outputs (output0, output1) of a segmentation export, found {}",
        g.output.len()
    );
    // Class names from ultralytics' `names` metadata ({0: 'a', 1: 'b'}).
    let names_meta = eng
        .metadata("names")
        .with_context(|| format!("{p}: no `names` metadata (not an ultralytics-layout export)"))?;
    let names = parse_names(names_meta).with_context(|| format!("{p}: metadata names"))?;
    let ids: Vec<u64> = match eng.metadata("chicktrain_category_ids") {
        Some(v) => serde_json::from_str(v)
            .with_context(|| format!("{p}: metadata chicktrain_category_ids {v:?}"))?,
        None => (1..=names.len() as u64).collect(),
    };
    ensure!(
        ids.len() == names.len(),
        "{p}: {} category ids for {} names",
        ids.len(),
        names.len()
    );
    Ok(OnnxModelInfo {
        size: h,
        num_classes: names.len(),
        classes: PredictClasses {
            category_ids: ids,
            names,
        },
    })
}

/// Parses the Python dict literal ultralytics writes for `names` (`{0: 'a', 1: "b"}`).
fn parse_names(s: &str) -> Result<Vec<String>> {
    let body = s
        .trim()
        .strip_prefix('{')
        .and_then(|b| b.strip_suffix('}'))
        .with_context(|| format!("{s:?} is not a {{index: 'name'}} dict"))?;
    let mut out = Vec::new();
    let mut chars = body.chars().peekable();
    loop {
        while chars.peek().is_some_and(|c| c.is_whitespace() || *c == ',') {
            chars.next();
        }
        if chars.peek().is_none() {
            break;
        }
        let idx: String = chars.by_ref().take_while(|c| *c != ':').collect();
        let idx: usize = idx
            .trim()
            .parse()
            .with_context(|| format!("bad class index {idx:?} in {s:?}"))?;
        ensure!(
            idx == out.len(),
            "class indices in {s:?} are not 0, 1, 2, …"
        );
        while chars.peek().is_some_and(|c| c.is_whitespace()) {
            chars.next();
        }
        let q = chars.next().filter(|c| *c == '\'' || *c == '"');
        let q = q.with_context(|| format!("class {idx} in {s:?} is not a quoted string"))?;
        let mut name = String::new();
        loop {
            match chars.next() {
                Some('\\') => match chars.next() {
                    Some('n') => name.push('\n'),
                    Some(c) => name.push(c),
                    None => bail!("unterminated class name in {s:?}"),
                },
                Some(c) if c == q => break,
                Some(c) => name.push(c),
                None => bail!("unterminated class name in {s:?}"),
            }
        }
        out.push(name);
    }
    ensure!(!out.is_empty(), "no class names in {s:?}");
    Ok(out)
}

/// `chicktrain predict --onnx model.onnx --input IMG_OR_DIR --out DIR`: the exported
/// file through tract, ultralytics-layout postprocess, the outputs of `predict`.
pub fn predict_onnx(
    onnx: &Path,
    input: &Path,
    out_dir: &Path,
    opts: &PredictOptions,
    threads: Option<usize>,
) -> Result<String> {
    set_threads(threads.unwrap_or_else(all_cores));
    let eng = TractEngine::load(onnx, Some(1))?;
    if eng.metadata("chicktrain_model") == Some("maskrcnn") {
        return predict_maskrcnn_onnx(eng, input, out_dir, opts);
    }
    let info = model_info(&eng)?;
    let size = info.size;
    let nc = info.num_classes;
    let text = predict_images(
        input,
        out_dir,
        size as u32,
        &info.classes,
        opts,
        &mut |px| {
            let out = eng.run(&[1, 3, size, size], &px)?;
            let (o0, o1) = (&out[0], &out[1]);
            ensure!(
                o0.shape.len() == 3 && o1.shape.len() == 4 && o0.shape[1] == 4 + nc + o1.shape[1],
                "{}: outputs {:?} and {:?} are not [1, 4 + {nc} + nm, A] and [1, nm, H, W]",
                onnx.display(),
                o0.shape,
                o1.shape
            );
            let s0 = [o0.shape[0], o0.shape[1], o0.shape[2]];
            let s1 = [o1.shape[0], o1.shape[1], o1.shape[2], o1.shape[3]];
            Ok(postprocess_layout(
                (&o0.data, s0),
                (&o1.data, s1),
                nc,
                [size, size],
                (opts.conf, opts.iou, opts.max_det),
            )
            .swap_remove(0))
        },
    )?;
    Ok(format!("{text} (tract, {})", onnx.display()))
}

/// `predict --onnx` of a Mask R-CNN export: the three graphs through tract, everything
/// between them (anchors, proposals, RoIAlign, box decoding, NMS, masks) by chicktrain's
/// own code, so the detections are those of `predict --checkpoint` up to the engines'
/// float differences.
fn predict_maskrcnn_onnx(
    eng: TractEngine,
    input: &Path,
    out_dir: &Path,
    opts: &PredictOptions,
) -> Result<String> {
    let p = eng.path.clone();
    let pd = p.display();
    let meta = |k: &str| {
        eng.metadata(k).map(str::to_string).with_context(|| {
            format!("{pd}: no `{k}` metadata (not a chicktrain Mask R-CNN export)")
        })
    };
    let cfg: MaskRcnnConfig = serde_json::from_str(&meta("chicktrain_maskrcnn")?)
        .with_context(|| format!("{pd}: metadata chicktrain_maskrcnn"))?;
    let names: Vec<String> =
        serde_json::from_str(&meta("names")?).with_context(|| format!("{pd}: metadata names"))?;
    let ids: Vec<u64> = serde_json::from_str(&meta("chicktrain_category_ids")?)
        .with_context(|| format!("{pd}: metadata chicktrain_category_ids"))?;
    ensure!(
        names.len() == cfg.num_classes && ids.len() == cfg.num_classes,
        "{pd}: {} names and {} category ids for {} classes",
        names.len(),
        ids.len(),
        cfg.num_classes
    );
    let s = &eng.input_shape;
    let size = match s.as_slice() {
        [_, Some(3), Some(h), Some(w)] if h == w => *h,
        _ => bail!(
            "{pd}: input must be [B, 3, S, S] with a fixed square size, the file declares {s:?}"
        ),
    };
    let dir = p.parent().unwrap_or(Path::new("."));
    let head = |k: &str| -> Result<TractEngine> {
        let f = dir.join(meta(k)?);
        TractEngine::load(&f, None).with_context(|| format!("the {k} graph of {pd}"))
    };
    let net = OnnxMaskRcnn {
        box_head: head("box_head")?,
        mask_head: head("mask_head")?,
        backbone: eng,
        device: Device::flex(),
    };
    let classes = PredictClasses {
        category_ids: ids,
        names,
    };
    let text = predict_images(input, out_dir, size as u32, &classes, opts, &mut |px| {
        let x = Tensor::<4>::from_data(TensorData::new(px, [1, 3, size, size]), &net.device);
        let mut d = infer(&net, &cfg, x)?.swap_remove(0);
        d.retain(|x| x.score >= opts.conf);
        Ok(nms_detections(d, opts.iou, opts.max_det))
    })?;
    Ok(format!(
        "{text} (tract, {} + its two RoI head graphs)",
        p.display()
    ))
}

fn all_cores() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// `bench engines` as given on the command line.
#[derive(Clone, Debug, clap::Args)]
pub struct EnginesRequest {
    /// Comma-separated YOLO variants (see `bench models --help`).
    #[arg(long, default_value = "yolo-n")]
    pub variants: String,
    /// Comma-separated input sizes.
    #[arg(long, default_value = "256,640")]
    pub sizes: String,
    /// Timed runs per engine and size; the median is reported.
    #[arg(long, default_value_t = 10)]
    pub repeats: usize,
    /// Untimed runs before the timed ones.
    #[arg(long, default_value_t = 2)]
    pub warmup: usize,
    /// tract threads (default: every core; flex always uses every core).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Also write each exported file here (<variant>_<size>.onnx).
    #[arg(long)]
    pub save_onnx: Option<PathBuf>,
}

/// `chicktrain bench engines --variants yolo-n --sizes 256,640`: flex vs tract latency.
pub fn bench_engines_cmd(r: &EnginesRequest) -> Result<String> {
    let vs = r
        .variants
        .split(',')
        .map(|v| v.trim().parse())
        .collect::<Result<Vec<Variant>>>()?;
    let sizes = parse_sizes(&r.sizes)?;
    bench_engines(
        &vs,
        &sizes,
        r.warmup,
        r.repeats,
        r.threads.unwrap_or_else(all_cores),
        r.save_onnx.as_deref(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_parse_as_python_writes_them() {
        assert_eq!(parse_names("{0: 'carcass'}").unwrap(), ["carcass"]);
        assert_eq!(
            parse_names(r#"{0: 'a', 1: "b c", 2: 'it\'s'}"#).unwrap(),
            ["a", "b c", "it's"]
        );
        assert!(parse_names("{1: 'a'}")
            .unwrap_err()
            .to_string()
            .contains("not 0, 1, 2"));
        assert!(parse_names("['a']").is_err());
        assert!(parse_names("{0: a}").is_err());
    }

    #[test]
    fn safetensors_layout() {
        let f = safetensors_f32(&[("x", &[2], &[1.0, 2.0]), ("y", &[1, 1], &[3.0])]);
        let n = u64::from_le_bytes(f[..8].try_into().unwrap()) as usize;
        assert_eq!(n % 8, 0);
        let h: serde_json::Value = serde_json::from_slice(&f[8..8 + n]).unwrap();
        assert_eq!(h["y"]["data_offsets"], serde_json::json!([8, 12]));
        assert_eq!(f.len(), 8 + n + 12);
        assert_eq!(&f[8 + n + 8..], &3.0f32.to_le_bytes());
    }
}
