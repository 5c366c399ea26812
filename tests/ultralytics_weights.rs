//! ultralytics weights in and out, against files ultralytics 8.4.190 / torch 2.15 wrote
//! (`tests/fixtures/ultralytics/make_fixtures.py`): the key mapping equals ultralytics' own
//! state_dict keys and shapes, a checkpoint as its trainer saves it loads and gives its
//! forward outputs, the safetensors export reads back bit for bit, bad files are refused by
//! name. No Python at test time.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use burn::tensor::{Device, Tensor, TensorData};
use chicktrain::model::yolo::ultralytics::{
    apply_all, exported_keys, from_state_dict, read_ultralytics, ultralytics_state_dict,
};
use chicktrain::model::yolo::{Scale, YoloSegConfig};
use chicktrain::util::tensor::to_host;
use chicktrain::weights::host::{HostData, HostTensor};
use chicktrain::weights::safetensors;
use chicktrain::weights::state_dict::read_state_dict;

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/ultralytics")
        .join(name)
}

/// chicktrain's config of the fixture model: ultralytics scale `t` = [0.50, 0.125, 1024] is
/// scale n at half width.
fn tiny_cfg(nc: usize) -> YoloSegConfig {
    YoloSegConfig::new(Scale::N, nc)
        .with_width_mult(0.5)
        .with_input_size(64)
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("ct-ultra-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
fn key_mapping_equals_ultralytics_state_dicts() {
    let text = std::fs::read_to_string(fixture("keys.json")).unwrap();
    let j: serde_json::Value = serde_json::from_str(&text).unwrap();
    let models = j["models"].as_object().unwrap();
    let theirs = |name: &str| -> BTreeMap<String, Vec<usize>> {
        models[name]
            .as_array()
            .unwrap()
            .iter()
            .map(|e| {
                let shape = e[1]
                    .as_array()
                    .unwrap()
                    .iter()
                    .map(|x| x.as_u64().unwrap() as usize)
                    .collect();
                (e[0].as_str().unwrap().to_string(), shape)
            })
            .collect()
    };
    for (name, scale, nc) in [
        ("yolo11n-seg nc1", Scale::N, 1),
        ("yolo11n-seg nc80", Scale::N, 80),
        ("yolo11s-seg nc1", Scale::S, 1),
        ("yolo11s-seg nc80", Scale::S, 80),
    ] {
        let ours = exported_keys(&YoloSegConfig::new(scale, nc)).unwrap();
        let reference = theirs(name);
        assert_eq!(ours.len(), reference.len(), "{name}: key count");
        for (k, shape) in &reference {
            assert_eq!(ours.get(k), Some(shape), "{name}: {k}");
        }
    }
    // The detection model is the segmentation model without its mask head.
    let seg = exported_keys(&YoloSegConfig::new(Scale::N, 80)).unwrap();
    let det: BTreeMap<_, _> = seg
        .into_iter()
        .filter(|(k, _)| !k.starts_with("model.23.proto.") && !k.starts_with("model.23.cv4."))
        .collect();
    assert_eq!(det, theirs("yolo11n nc80"));
}

fn expected_tensor(e: &serde_json::Value) -> (Vec<usize>, Vec<f64>, String) {
    (
        e["shape"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_u64().unwrap() as usize)
            .collect(),
        e["values"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect(),
        e["dtype"].as_str().unwrap().to_string(),
    )
}

#[test]
fn reads_state_dicts_modules_and_safetensors_as_torch_wrote_them() {
    let text = std::fs::read_to_string(fixture("reader/expected.json")).unwrap();
    let j: serde_json::Value = serde_json::from_str(&text).unwrap();
    for (file, origin) in [
        ("state_dict.pt", "state dict"),
        ("stripped.pt", "model"),
        ("small.safetensors", "safetensors"),
    ] {
        let sd = read_state_dict(&fixture(&format!("reader/{file}")), &["ema", "model"]).unwrap();
        assert_eq!(sd.origin, origin, "{file}");
        let exp = j[file].as_object().unwrap();
        let got: Vec<&String> = sd.tensors.keys().collect();
        let want: Vec<&String> = exp.keys().collect();
        assert_eq!(
            got, want,
            "{file}: names (the non-persistent buffer is left out)"
        );
        for (k, e) in exp {
            let (shape, values, dtype) = expected_tensor(e);
            let t = &sd.tensors[k];
            assert_eq!(t.shape, shape, "{file} {k}");
            assert_eq!(t.source_dtype, dtype, "{file} {k}");
            let v: Vec<f64> = match &t.data {
                HostData::F32(v) => v.iter().map(|&x| x as f64).collect(),
                HostData::I64(v) => v.iter().map(|&x| x as f64).collect(),
            };
            // f16 / f32 values are exact in f32; the JSON holds their f64 expansion.
            let v32: Vec<f32> = values.iter().map(|&x| x as f32).collect();
            assert_eq!(
                v.iter().map(|&x| x as f32).collect::<Vec<_>>(),
                v32,
                "{file} {k}"
            );
        }
    }
}

fn forward_reference() -> BTreeMap<String, HostTensor> {
    safetensors::read(&fixture("tiny_seg_forward.safetensors")).unwrap()
}

fn max_abs_diff(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f32::max)
}

#[test]
fn ultralytics_checkpoint_gives_ultralytics_outputs() {
    let cfg = tiny_cfg(2);
    let w = read_ultralytics(&fixture("tiny_seg.pt"), &cfg).unwrap();
    assert!(
        w.class_unfit.is_empty() && w.missing.is_empty(),
        "{:?}",
        w.notes
    );
    assert_eq!(w.file_classes, 2);
    assert!(w.notes[0].contains("from the ema of"), "{:?}", w.notes);
    assert!(w.notes[0].contains("float16"), "{:?}", w.notes);
    let d = Device::flex();
    let model = apply_all(cfg.init(&d), &w).unwrap();

    let r = forward_reference();
    let img = &r["images"];
    let x = Tensor::<4>::from_data(TensorData::new(img.to_f32(), [1, 3, 64, 96]), &d);
    let out = model.forward(x);
    let mut worst = Vec::new();
    for (name, got) in [
        ("boxes", to_host(out.box_dist)),
        ("scores", to_host(out.cls_logits)),
        ("mask_coefficient", to_host(out.mask_coef)),
    ] {
        let want = r[name].to_f32();
        let e = max_abs_diff(&got, &want);
        worst.push((name, e));
        assert!(e <= 1e-4, "{name}: max |Δ| {e}");
    }
    assert_eq!(out.proto.dims(), [1, 32, 16, 24]);
    let e = max_abs_diff(&to_host(out.proto), &r["proto"].to_f32());
    worst.push(("proto", e));
    assert!(e <= 1e-4, "proto: max |Δ| {e}");
    eprintln!("max |chicktrain − ultralytics| per output: {worst:?}");
}

#[test]
fn safetensors_export_reads_back_bit_for_bit() {
    let cfg = tiny_cfg(2);
    let d = Device::flex();
    let file = fixture("tiny_seg.pt");
    let model = apply_all(cfg.init(&d), &read_ultralytics(&file, &cfg).unwrap()).unwrap();
    let sd = ultralytics_state_dict(&model, &cfg).unwrap();

    // The export is the checkpoint's own state dict: same keys, shapes and (fp16-exact)
    // values; only num_batches_tracked differs (Burn does not count batches).
    let orig = read_state_dict(&file, &["ema", "model"]).unwrap().tensors;
    assert_eq!(sd.len(), orig.len());
    for (k, t) in &sd {
        let o = orig
            .get(k)
            .unwrap_or_else(|| panic!("{k} not in the checkpoint"));
        assert_eq!(t.shape, o.shape, "{k}");
        if k.ends_with("num_batches_tracked") {
            assert_eq!(t.data, HostData::I64(vec![0]));
            assert_eq!(o.data, HostData::I64(vec![7]));
        } else {
            assert_eq!(t.data, o.data, "{k}");
        }
    }

    let dir = tmp("export");
    let out = dir.join("tiny.safetensors");
    safetensors::write(&out, &sd, &BTreeMap::new()).unwrap();
    let back = apply_all(cfg.init(&d), &read_ultralytics(&out, &cfg).unwrap()).unwrap();
    let sd2 = ultralytics_state_dict(&back, &cfg).unwrap();
    assert_eq!(sd.len(), sd2.len());
    for ((k, a), (k2, b)) in sd.iter().zip(&sd2) {
        assert_eq!(k, k2);
        match (&a.data, &b.data) {
            (HostData::F32(x), HostData::F32(y)) => assert!(
                x.iter().zip(y).all(|(p, q)| p.to_bits() == q.to_bits()),
                "{k} differs after the round trip"
            ),
            (x, y) => assert_eq!(x, y, "{k}"),
        }
    }
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn another_class_count_leaves_the_class_head_out() {
    let file = fixture("tiny_seg.pt");
    // nc 1: only the last 1×1 conv of each level's class branch changes (weight + bias × 3).
    let w = read_ultralytics(&file, &tiny_cfg(1)).unwrap();
    assert_eq!(w.file_classes, 2);
    assert_eq!(w.class_unfit.len(), 6, "{:?}", w.class_unfit);
    assert!(w
        .class_unfit
        .iter()
        .all(|u| u.theirs.starts_with("model.23.cv3.") && u.theirs.contains(".2.")));
    assert!(
        w.notes.iter().any(|n| n.contains("2 classes, the model 1")),
        "{:?}",
        w.notes
    );
    let full = read_ultralytics(&file, &tiny_cfg(2)).unwrap();
    assert_eq!(w.snapshots.len() + 6, full.snapshots.len());
    // nc 80 widens the class branch too (c3 = max(ch, min(nc, 100))): all of it is left out,
    // nothing else.
    let w80 = read_ultralytics(&file, &tiny_cfg(80)).unwrap();
    assert!(w80.class_unfit.len() > 6);
    assert!(w80
        .class_unfit
        .iter()
        .all(|u| u.theirs.starts_with("model.23.cv3.")));
    assert!(apply_all(tiny_cfg(80).init(&Device::flex()), &w80)
        .unwrap_err()
        .to_string()
        .contains("model.23.cv3"));
}

#[test]
fn a_detection_checkpoint_leaves_the_mask_head_out() {
    let file = fixture("tiny_seg.pt");
    let mut sd = read_state_dict(&file, &["ema", "model"]).unwrap();
    sd.tensors
        .retain(|k, _| !k.starts_with("model.23.proto.") && !k.starts_with("model.23.cv4."));
    let w = from_state_dict(&sd, Path::new("det.pt"), &tiny_cfg(2)).unwrap();
    assert!(!w.missing.is_empty());
    assert!(w
        .missing
        .iter()
        .all(|p| p.starts_with("head.proto.") || p.starts_with("head.coef.")));
    assert!(w.notes.iter().any(|n| n.contains("detection checkpoint")));
    assert!(w.class_unfit.is_empty());
}

#[test]
fn bad_files_are_refused_by_name() {
    let cfg = tiny_cfg(2);
    let dir = tmp("bad");
    let err =
        |p: &Path, cfg: &YoloSegConfig| format!("{:#}", read_ultralytics(p, cfg).unwrap_err());

    let bytes = std::fs::read(fixture("tiny_seg.pt")).unwrap();
    let cut = dir.join("truncated.pt");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let e = err(&cut, &cfg);
    assert!(e.contains("truncated.pt") && e.contains("truncated"), "{e}");

    let e = err(&fixture("keys.json"), &cfg);
    assert!(e.contains("keys.json is not a PyTorch checkpoint"), "{e}");

    // The same checkpoint read as scale n at full width: the first layer's shape is named.
    let e = err(&fixture("tiny_seg.pt"), &YoloSegConfig::new(Scale::N, 2));
    assert!(
        e.contains("tiny_seg.pt: model.0.conv.weight has shape [8, 3, 3, 3] in the file")
            && e.contains("needs [16, 3, 3, 3]"),
        "{e}"
    );

    let e = err(&fixture("reader/state_dict.pt"), &cfg);
    assert!(e.contains("not an ultralytics YOLO state dict"), "{e}");

    let st = std::fs::read(fixture("tiny_seg_forward.safetensors")).unwrap();
    let cut = dir.join("cut.safetensors");
    std::fs::write(&cut, &st[..st.len() - 10]).unwrap();
    let e = format!("{:#}", read_state_dict(&cut, &[]).unwrap_err());
    assert!(
        e.contains("cut.safetensors") && e.contains("truncated"),
        "{e}"
    );

    let e = err(&dir.join("absent.pt"), &cfg);
    assert!(e.contains("absent.pt does not exist"), "{e}");
    std::fs::remove_dir_all(dir).unwrap();
}

mod common;

/// A checkpoint whose `ema` weights are the fixture's (header as `train` writes it).
fn checkpoint_of(
    model: chicktrain::infer::detector::Detector,
    cfg: chicktrain::infer::detector::DetectorConfig,
    path: &Path,
) {
    use chicktrain::annotations::split::Split;
    use chicktrain::infer::checkpoint::{module_bytes, Checkpoint, Header, FORMAT};
    let config = chicktrain::config::parse(chicktrain::config::SHIPPED[0].1, "q", &[]).unwrap();
    let nc = cfg.num_classes();
    Checkpoint {
        header: Header {
            format: FORMAT,
            chicktrain: "test".into(),
            model: cfg,
            category_ids: (1..=nc as u64).collect(),
            class_names: ["carcass", "wing"]
                .iter()
                .take(nc)
                .map(|s| s.to_string())
                .collect(),
            config,
            split: Split::new(&[1, 2, 3], [0.34, 0.33], 0).unwrap(),
            proxy: true,
            epoch: 3,
            ema_updates: 9,
            best_fitness: 0.5,
            val: None,
            loss_scale: None,
        },
        sections: vec![("ema".into(), module_bytes(&model).unwrap())],
    }
    .save(path)
    .unwrap();
}

#[test]
fn export_command_writes_the_ultralytics_state_dict() {
    use chicktrain::infer::detector::{Detector, DetectorConfig};
    let cfg = tiny_cfg(2);
    let file = fixture("tiny_seg.pt");
    let model = apply_all(
        cfg.init(&Device::flex()),
        &read_ultralytics(&file, &cfg).unwrap(),
    )
    .unwrap();
    let dir = common::tmp("ultra-export");
    let ckpt = dir.join("best.bpk");
    checkpoint_of(
        Detector::Yolo(model),
        DetectorConfig::Yolo(cfg.clone()),
        &ckpt,
    );

    let out = common::export(ckpt.to_str().unwrap(), "safetensors", &[]);
    common::assert_success(&out);
    let st = dir.join("best.safetensors");
    assert!(String::from_utf8_lossy(&out.stdout).contains("best.safetensors"));
    let (tensors, meta) = safetensors::parse(&std::fs::read(&st).unwrap()).unwrap();
    assert_eq!(meta["ultralytics_scale"], "[0.5,0.125,1024]");
    assert_eq!((meta["nc"].as_str(), meta["nm"].as_str()), ("2", "32"));
    assert_eq!(meta["names"], r#"{"0":"carcass","1":"wing"}"#);
    // Bit for bit the checkpoint's tensors, under ultralytics' names (fp16-exact values).
    let orig = read_state_dict(&file, &["ema", "model"]).unwrap().tensors;
    assert_eq!(tensors.len(), orig.len());
    for (k, t) in &tensors {
        if !k.ends_with("num_batches_tracked") {
            assert_eq!(t.data, orig[k].data, "{k}");
        }
    }

    // Mask R-CNN has no safetensors export (torchvision names) yet: a clear error, no file.
    let mr = common::tiny::tiny_maskrcnn(
        64,
        common::tiny::TinyWidths {
            fpn: 16,
            fc: 32,
            mask_conv: 16,
            mask_convs: 1,
        },
    );
    let mr_ckpt = dir.join("mrcnn.bpk");
    checkpoint_of(
        Detector::MaskRcnn(mr.init(&Device::flex())),
        DetectorConfig::Maskrcnn(mr),
        &mr_ckpt,
    );
    let out = common::export(mr_ckpt.to_str().unwrap(), "safetensors", &[]);
    // Mask R-CNN exports under torchvision's names (tests/torchvision_import.rs checks
    // the contents); here only that the shared command takes the other family.
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(dir.join("mrcnn.safetensors").exists());
    let out = common::export(
        file.to_str().unwrap(),
        "safetensors",
        &["--out", dir.join("x.safetensors").to_str().unwrap()],
    );
    common::assert_clean_error(&out, &["tiny_seg.pt is not a chicktrain checkpoint"]);
    assert!(!dir.join("x.safetensors").exists());
    std::fs::remove_dir_all(dir).unwrap();
}

/// `model.init` with an ultralytics `.pt` (the trainer-format fixture, 2 classes), through
/// the dispatch the trainer uses: into a 2-class model every tensor loads, equal to the
/// strict path; into a 1-class model the class branch starts fresh and is named; into a
/// model without C2PSA (another layer numbering) a clear error naming the file.
#[test]
fn model_init_takes_an_ultralytics_checkpoint() {
    use chicktrain::infer::detector::{Detector, DetectorConfig};
    use chicktrain::model::weights::{collect, snapshot_data};
    use chicktrain::train::init::load_init;
    let dev = Device::flex();
    let file = fixture("tiny_seg.pt");
    let c2 = tiny_cfg(2);
    let cfg = DetectorConfig::Yolo(c2.clone());
    let (det, note) = load_init(cfg.init(&dev), &cfg, &file, &dev).unwrap();
    assert!(
        note.contains("ultralytics") && !note.contains("fresh initialisation"),
        "{note}"
    );
    let Detector::Yolo(m) = det else {
        panic!("not a YOLO")
    };
    let strict = apply_all(c2.init(&dev), &read_ultralytics(&file, &c2).unwrap()).unwrap();
    let (a, b) = (collect(&m), collect(&strict));
    assert_eq!(a.len(), b.len());
    for (x, y) in a.into_iter().zip(b) {
        assert_eq!(x.name, y.name);
        let name = x.name.clone();
        let (x, y) = (snapshot_data(x).unwrap(), snapshot_data(y).unwrap());
        assert_eq!(
            x.try_to_vec::<f32>().unwrap(),
            y.try_to_vec::<f32>().unwrap(),
            "{name}"
        );
    }

    let c1 = DetectorConfig::Yolo(tiny_cfg(1));
    let (_, note) = load_init(c1.init(&dev), &c1, &file, &dev).unwrap();
    assert!(
        note.contains("keep their fresh initialisation") && note.contains("head.cls"),
        "{note}"
    );

    let c3 = DetectorConfig::Yolo(tiny_cfg(2).with_c2psa(false));
    let e = format!(
        "{:#}",
        load_init(c3.init(&dev), &c3, &file, &dev).unwrap_err()
    );
    assert!(e.contains("tiny_seg.pt") && e.contains("C2PSA"), "{e}");
}
