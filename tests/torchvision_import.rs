//! torchvision import parity (issue 15 §1): state dicts written by torchvision 0.29
//! (`tests/fixtures/torchvision/make_fixtures.py`: random init, torchvision's own classes at
//! 1/8 width, fp16) load into chicktrain's Mask R-CNN and give torchvision's eval-mode
//! outputs: ResNet-18 stages C2–C5 from a `torch.save` file and from a safetensors file,
//! and for a `maskrcnn_resnet50_fpn`-layout model the FPN levels P2–P6, the RPN objectness
//! logits and deltas, the box head + predictor and the mask head + predictor (background
//! class moved/dropped). Tolerance: |ours − torchvision| ≤ 1e-4 · max(1, |torchvision|).
//! Mapping errors name the first key that does not fit; truncated files name the file.
//! The export (`torchvision_state_dict`) gives the fixture's state dict back.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use burn::tensor::{Device, Tensor, TensorData};
use chicktrain::infer::detector::{Detector, DetectorConfig};
use chicktrain::model::maskrcnn::mask_head::MaskHeadConfig;
use chicktrain::model::maskrcnn::roi_heads::RoiHeadsConfig;
use chicktrain::model::maskrcnn::torchvision::{
    class_dependent, map_state_dict, torchvision_state_dict, TorchvisionKind,
};
use chicktrain::model::maskrcnn::{MaskRcnnConfig, STRIDES};
use chicktrain::model::weights::{self, apply_named, snapshot_data};
use chicktrain::train::init::load_init;
use chicktrain::weights::host::HostData;

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/torchvision")
        .join(name)
}

fn reference() -> HashMap<String, TensorData> {
    weights::read_file(&fixture("reference.safetensors"), &[])
        .unwrap()
        .into_iter()
        .map(|s| (s.name.clone(), snapshot_data(s).unwrap()))
        .collect()
}

fn tensor<const D: usize>(d: &TensorData, dev: &Device) -> Tensor<D> {
    Tensor::from_data(d.clone(), dev)
}

/// Largest |a − b| / max(1, |b|), after checking the shapes agree.
fn rel_err(what: &str, ours: Vec<f32>, ours_shape: &[usize], want: &TensorData) -> f64 {
    assert_eq!(ours_shape, want.shape().as_slice(), "{what}: shape");
    let w = want.to_vec_f32();
    assert_eq!(ours.len(), w.len(), "{what}: length");
    ours.iter()
        .zip(&w)
        .map(|(a, b)| ((a - b).abs() / b.abs().max(1.0)) as f64)
        .fold(0.0, f64::max)
}

trait F32 {
    fn to_vec_f32(&self) -> Vec<f32>;
}
impl F32 for TensorData {
    fn to_vec_f32(&self) -> Vec<f32> {
        self.clone().convert::<f32>().try_to_vec::<f32>().unwrap()
    }
}

fn host<const D: usize>(t: Tensor<D>) -> (Vec<f32>, Vec<usize>) {
    let dims = t.dims().to_vec();
    (t.into_data().to_vec_f32(), dims)
}

const TOL: f64 = 1e-4;

fn check<const D: usize>(what: &str, t: Tensor<D>, want: &TensorData) {
    let (v, s) = host(t);
    let e = rel_err(what, v, &s, want);
    eprintln!("{what}: max relative error {e:.2e}");
    assert!(e <= TOL, "{what}: max relative error {e:e} > {TOL:e}");
}

/// `model.init` of `path` into a fresh model of `cfg`.
fn init_from(cfg: MaskRcnnConfig, path: &Path, dev: &Device) -> anyhow::Result<(Detector, String)> {
    let c = DetectorConfig::Maskrcnn(cfg);
    load_init(c.init(dev), &c, path, dev)
}

/// The model the Mask R-CNN fixture describes: paper preset, R50 at width ×0.125, 16-wide
/// FPN, 32-wide box FCs, 16-wide mask convs, one class, 64 px input.
fn fixture_config() -> MaskRcnnConfig {
    fixture_layout(1).with_input_size(64)
}

/// The fixture's layers with `classes` classes (the paper preset's input size).
fn fixture_layout(classes: usize) -> MaskRcnnConfig {
    let p = MaskRcnnConfig::paper(50, classes);
    p.clone()
        .with_width_mult(0.125)
        .with_fpn_channels(16)
        .with_roi(RoiHeadsConfig {
            fc_dim: 32,
            ..p.roi.clone()
        })
        .with_mask(MaskHeadConfig {
            conv_dim: 16,
            ..p.mask.clone()
        })
}

#[test]
fn resnet18_state_dicts_give_torchvision_stages() {
    let dev = Device::flex();
    let r = reference();
    let x: Tensor<4> = tensor(&r["x"], &dev);
    for file in ["resnet18_w8.pth", "resnet18_w8.safetensors"] {
        let bytes = std::fs::read(fixture(file)).unwrap();
        match weights::sniff(&bytes) {
            Some(weights::Format::TorchZip | weights::Format::Safetensors) => {}
            f => panic!("{file}: {f:?}"),
        }
        let tensors = weights::read_file(&fixture(file), &[]).unwrap();
        let mapped = map_state_dict(tensors, 1).unwrap();
        assert_eq!(mapped.kind, TorchvisionKind::ResNet);
        let model = MaskRcnnConfig::new(18, 1).with_width_mult(0.125).init(&dev);
        let (model, applied) = apply_named(
            model,
            mapped.snapshots,
            &class_dependent(mapped.kind),
            file,
            &mapped.file_keys,
        )
        .unwrap();
        // 20 convs + 20 BatchNorms × 4 tensors (fc and num_batches_tracked dropped).
        assert_eq!(applied.loaded, 20 + 20 * 4, "{file}");
        assert!(applied
            .reinitialised
            .iter()
            .all(|p| !p.starts_with("backbone.")));
        let c = model.backbone.forward(x.clone());
        for (i, t) in c.into_iter().enumerate() {
            check(
                &format!("{file} C{}", i + 2),
                t,
                &r[&format!("r18.c{}", i + 2)],
            );
        }
    }
}

#[test]
fn maskrcnn_state_dict_gives_torchvision_features_rpn_and_heads() {
    let dev = Device::flex();
    let r = reference();
    let path = fixture("maskrcnn_r50_w8.pth");
    let (det, note) = init_from(fixture_config(), &path, &dev).unwrap();
    eprintln!("{note}");
    assert!(
        note.contains("torchvision Mask R-CNN (2 classes with background)"),
        "{note}"
    );
    assert!(
        !note.contains("fresh initialisation"),
        "2 classes = 1 + background: all load: {note}"
    );
    let Detector::MaskRcnn(m) = det else { panic!() };
    let x: Tensor<4> = tensor(&r["x"], &dev);
    let feats = m.fpn.forward(m.backbone.forward(x));
    for (i, f) in feats.iter().enumerate() {
        check(
            &format!("P{}", i + 2),
            f.clone(),
            &r[&format!("mr.p{}", i + 2)],
        );
    }
    let rpn = m.rpn.forward(&feats, &STRIDES);
    check("RPN objectness logits", rpn.logits, &r["mr.rpn_logits"]);
    check("RPN deltas", rpn.deltas, &r["mr.rpn_deltas"]);

    // Box head: torchvision's logits are (background, carcass), ours (carcass,
    // background); its deltas carry the background's 4 first.
    let (cls, deltas) = m.box_head.forward(tensor(&r["mr.pooled"], &dev));
    let t_cls = r["mr.cls"].to_vec_f32();
    let want_cls: Vec<f32> = t_cls.chunks(2).flat_map(|c| [c[1], c[0]]).collect();
    check(
        "box head class logits",
        cls,
        &TensorData::new(want_cls, [3, 2]),
    );
    let t_box = r["mr.box"].to_vec_f32();
    let want_box: Vec<f32> = t_box.chunks(8).flat_map(|c| c[4..].to_vec()).collect();
    check(
        "box head deltas",
        deltas,
        &TensorData::new(want_box, [3, 4]),
    );
    let mask = m.mask_head.forward(tensor(&r["mr.mask_in"], &dev));
    let t_mask = r["mr.mask"].to_vec_f32();
    let want_mask: Vec<f32> = t_mask
        .chunks(2 * 28 * 28)
        .flat_map(|c| c[28 * 28..].to_vec())
        .collect();
    check(
        "mask logits",
        mask,
        &TensorData::new(want_mask, [3, 1, 28, 28]),
    );
}

/// Export is the import read backwards: the model imported from the torchvision fixture
/// gives back the fixture's state dict — every key, shape and value bit for bit — except
/// the background's box deltas and mask logits, which chicktrain does not keep and writes
/// as zeros (torchvision's inference never reads them).
#[test]
fn export_gives_the_torchvision_state_dict_back() {
    let dev = Device::flex();
    let path = fixture("maskrcnn_r50_w8.pth");
    let (det, _) = init_from(fixture_config(), &path, &dev).unwrap();
    let Detector::MaskRcnn(m) = det else { panic!() };
    let exported = torchvision_state_dict(&m).unwrap();
    let file: HashMap<String, TensorData> = weights::read_file(&path, &[])
        .unwrap()
        .into_iter()
        .filter(|s| !s.name.ends_with("num_batches_tracked"))
        .map(|s| (s.name.clone(), snapshot_data(s).unwrap()))
        .collect();
    assert_eq!(exported.len(), file.len(), "tensor count");
    for (k, t) in &exported {
        let want = file
            .get(k)
            .unwrap_or_else(|| panic!("{k} is not a torchvision key"));
        assert_eq!(&t.shape, &want.shape().to_vec(), "{k}: shape");
        let HostData::F32(v) = &t.data else {
            panic!("{k}: not f32")
        };
        let mut w = want.to_vec_f32();
        // The background's rows: 4 box deltas (bias [4], weight rows [4, in]), one mask
        // channel.
        let bg = match k.as_str() {
            "roi_heads.box_predictor.bbox_pred.bias" => 4,
            "roi_heads.box_predictor.bbox_pred.weight" => 4 * t.shape[1],
            "roi_heads.mask_predictor.mask_fcn_logits.bias" => 1,
            "roi_heads.mask_predictor.mask_fcn_logits.weight" => t.shape[1..].iter().product(),
            _ => 0,
        };
        assert!(
            v[..bg].iter().all(|x| *x == 0.0),
            "{k}: background not zero"
        );
        w[..bg].iter_mut().for_each(|x| *x = 0.0);
        let same = v.iter().zip(&w).all(|(a, b)| a.to_bits() == b.to_bits());
        assert!(same, "{k}: values differ from the torchvision file");
    }
}

#[test]
fn other_class_counts_reinitialise_the_predictors_and_mismatches_name_the_key() {
    let dev = Device::flex();
    let path = fixture("maskrcnn_r50_w8.pth");
    // 3 classes here, 1 + background in the file: the three predictors stay fresh.
    let m3 = fixture_layout(3);
    let (_, note) = init_from(m3, &path, &dev).unwrap();
    assert!(
        note.contains("6 tensors keep their fresh initialisation"),
        "{note}"
    );
    for k in [
        "box_head.cls_score",
        "box_head.bbox_pred",
        "mask_head.predictor",
    ] {
        assert!(note.contains(k), "{note}");
    }

    // The ResNet-18 file into an R50 Mask R-CNN: the first stage block differs.
    let r50 = MaskRcnnConfig::new(50, 1).with_width_mult(0.125);
    let e = format!(
        "{:#}",
        init_from(r50, &fixture("resnet18_w8.pth"), &dev).unwrap_err()
    );
    assert!(e.contains("resnet18_w8.pth"), "{e}");
    assert!(
        e.contains("key backbone.stages.0.blocks.0.convs.0.conv.weight (file key layer1.0.conv1.weight) does not fit"),
        "{e}"
    );
    // The same file at the wrong width names the stem.
    let wide = MaskRcnnConfig::new(18, 1).with_width_mult(0.25);
    let e = format!(
        "{:#}",
        init_from(wide, &fixture("resnet18_w8.pth"), &dev).unwrap_err()
    );
    assert!(
        e.contains("backbone.stem.conv.weight (file key conv1.weight)")
            && e.contains("expects shape [16, 3, 7, 7], the file has [8, 3, 7, 7]"),
        "{e}"
    );

    // Truncated and garbage files are errors naming the file, never panics.
    let dir = std::env::temp_dir().join(format!("ct-tvimport-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    for (name, b) in [
        ("half.pth", bytes[..bytes.len() / 2].to_vec()),
        ("head.pth", bytes[..4000].to_vec()),
        ("garbage.pt", b"definitely not weights".to_vec()),
        ("empty.pt", Vec::new()),
    ] {
        let p = dir.join(name);
        std::fs::write(&p, &b).unwrap();
        let e = format!("{:#}", init_from(fixture_config(), &p, &dev).unwrap_err());
        assert!(e.contains(name), "{name}: {e}");
        eprintln!("{name}: {e}");
    }
    let e = format!(
        "{:#}",
        init_from(fixture_config(), &dir.join("missing.pth"), &dev).unwrap_err()
    );
    assert!(
        e.contains("missing.pth") && e.contains("cannot read"),
        "{e}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Full-size torchvision files (not committed: `full_size.py` writes them, see its
/// docstring): ImageNet ResNet-18/34/50/101 into the backbone of the same depth, and
/// `maskrcnn_resnet50_fpn` (v1, 2 and 91 classes) into the paper preset with one class.
#[test]
#[ignore = "needs CHICKTRAIN_TV_FULL=DIR from tests/fixtures/torchvision/full_size.py"]
fn full_size_torchvision_state_dicts_fit() {
    let dir = PathBuf::from(std::env::var("CHICKTRAIN_TV_FULL").expect("CHICKTRAIN_TV_FULL=DIR"));
    let dev = Device::flex();
    for depth in [18, 34, 50, 101] {
        let (_, note) = init_from(
            MaskRcnnConfig::new(depth, 1),
            &dir.join(format!("resnet{depth}.pth")),
            &dev,
        )
        .unwrap();
        eprintln!("R{depth}: {note}");
        assert!(
            note.contains("torchvision ResNet (backbone only)"),
            "{note}"
        );
    }
    let (_, note) = init_from(
        MaskRcnnConfig::paper(50, 1),
        &dir.join("maskrcnn_resnet50_fpn_2.pth"),
        &dev,
    )
    .unwrap();
    eprintln!("{note}");
    assert!(!note.contains("fresh initialisation"), "{note}");
    let (_, note) = init_from(
        MaskRcnnConfig::paper(50, 1),
        &dir.join("maskrcnn_resnet50_fpn_91.pth"),
        &dev,
    )
    .unwrap();
    eprintln!("{note}");
    assert!(
        note.contains("6 tensors keep their fresh initialisation"),
        "{note}"
    );
}

/// Corrupt files never panic: seeded byte flips in the zip headers, `data.pkl` and the
/// central directory of the fixture, and truncations anywhere, give `Ok` or an error
/// (the same for the safetensors fixture's header).
#[test]
fn corrupted_files_are_errors_not_panics() {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(15);
    for (file, safet) in [
        ("maskrcnn_r50_w8.pth", false),
        ("resnet18_w8.safetensors", true),
    ] {
        let good = std::fs::read(fixture(file)).unwrap();
        let dir = std::env::temp_dir().join(format!("ct-tvcorrupt-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let damaged = dir.join(file);
        let read = |b: &[u8]| {
            std::fs::write(&damaged, b).unwrap();
            weights::read_file(&damaged, &[]).map(|_| ())
        };
        let mut errors = 0;
        for i in 0..400 {
            let mut b = good.clone();
            if i % 4 == 0 {
                b.truncate(rng.random_range(0..good.len()));
            } else {
                // Structure lives at both ends: headers and data.pkl first, the central
                // directory (or, for safetensors, only the header) at the start or end.
                let n = good.len();
                for _ in 0..rng.random_range(1..8) {
                    let at = if rng.random_bool(0.5) || safet {
                        rng.random_range(0..8192.min(n))
                    } else {
                        rng.random_range(n.saturating_sub(8192)..n)
                    };
                    b[at] = rng.random();
                }
            }
            let r = std::panic::catch_unwind(|| read(&b));
            match r {
                Ok(Err(_)) => errors += 1,
                Ok(Ok(())) => {}
                Err(_) => panic!("{file}: mutation {i} panicked"),
            }
        }
        assert!(
            errors > 100,
            "{file}: only {errors} of 400 corruptions were noticed"
        );
    }
}
