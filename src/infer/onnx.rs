//! `predict --onnx`: a file written by `export --format onnx` run through tract, with the
//! postprocess and outputs of `predict --checkpoint` — YOLO-seg in ultralytics' layout
//! (class names from its `names` metadata), or a Mask R-CNN export's three graphs with
//! everything between them done by chicktrain's own code.

use std::path::Path;

use anyhow::{bail, ensure, Context, Result};
use burn::tensor::{Device, Tensor, TensorData};

use crate::model::maskrcnn::onnx::OnnxMaskRcnn;
use crate::model::maskrcnn::{infer, MaskRcnnConfig};
use crate::model::onnx::engine::{set_threads, TractEngine};
use crate::model::yolo::postprocess::postprocess_layout;
use crate::util::all_cores;

use super::predict::{predict_images, PredictClasses, PredictOptions};
use crate::model::detection::nms_detections;

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
}
