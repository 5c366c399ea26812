//! The bad-input matrix beyond configs and annotation JSON (those are in `cli.rs`): image
//! files through the COCO-folder and LabelMe loaders and `predict`, carcass meshes through
//! `render --carcass`, and checkpoints through `eval`, `predict` and `--resume`. Every
//! broken file is made here. Each case must exit 2 with one message naming the file and
//! the problem, never a panic; gray, 16-bit, RGBA and EXIF-rotated images are not errors:
//! they become RGB8 with the EXIF orientation applied (as ultralytics does), which the
//! training runs below prove (an EXIF-rotated image only matches its annotated size once
//! rotated).

mod common;

use std::path::{Path, PathBuf};

use chicktrain::infer::checkpoint::Checkpoint;
use chicktrain::infer::detector::DetectorConfig;
use common::*;
use image::ImageEncoder;

const S: u32 = 64;

/// A 48×64 JPEG whose EXIF orientation 6 (rotate 90° clockwise) makes it 64×48.
fn exif_rotated_jpeg(path: &Path) {
    let img = image::RgbImage::from_fn(48, 64, |x, y| image::Rgb([x as u8 * 4, y as u8 * 3, 90]));
    // TIFF (little endian): one IFD entry, Orientation (0x0112), SHORT, count 1, value 6.
    let mut tiff = b"II*\0".to_vec();
    tiff.extend(8u32.to_le_bytes());
    tiff.extend(1u16.to_le_bytes());
    tiff.extend([0x12, 0x01, 3, 0]);
    tiff.extend(1u32.to_le_bytes());
    tiff.extend([6, 0, 0, 0]);
    tiff.extend(0u32.to_le_bytes());
    let mut f = std::fs::File::create(path).unwrap();
    let mut enc = image::codecs::jpeg::JpegEncoder::new_with_quality(&mut f, 90);
    enc.set_exif_metadata(tiff).unwrap();
    enc.write_image(img.as_raw(), 48, 64, image::ExtendedColorType::Rgb8)
        .unwrap();
}

/// Writes image `name` in one of the accepted formats; returns its (width, height) as
/// annotated (after EXIF).
fn write_image(dir: &Path, name: &str) -> (u32, u32) {
    let p = dir.join(name);
    match name {
        n if n.starts_with("gray") => {
            image::GrayImage::from_fn(S, S, |x, _| image::Luma([x as u8 * 3]))
                .save(&p)
                .unwrap()
        }
        n if n.starts_with("deep") => {
            image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_fn(S, S, |x, y| {
                image::Luma([(x * y * 16) as u16])
            })
            .save(&p)
            .unwrap()
        }
        n if n.starts_with("rgba") => image::RgbaImage::from_fn(S, S, |x, y| {
            image::Rgba([x as u8 * 3, y as u8 * 3, 50, 128])
        })
        .save(&p)
        .unwrap(),
        n if n.starts_with("exif") => {
            exif_rotated_jpeg(&p);
            return (64, 48);
        }
        _ => image::RgbImage::from_fn(S, S, |x, y| image::Rgb([x as u8, y as u8, 200]))
            .save(&p)
            .unwrap(),
    }
    (S, S)
}

/// A COCO file ([`coco_path`]) and LabelMe files (`<stem>.json`) for `names` in `dir`,
/// one square instance each; sizes as annotated.
fn annotate(dir: &Path, names: &[(&str, (u32, u32))]) -> PathBuf {
    let mut images = Vec::new();
    let mut anns = Vec::new();
    for (i, (name, (w, h))) in names.iter().enumerate() {
        let id = i + 1;
        images.push(serde_json::json!({"id": id, "file_name": name, "width": w, "height": h}));
        anns.push(serde_json::json!({"id": id, "image_id": id, "category_id": 1,
            "segmentation": [[8, 8, 40, 8, 40, 40, 8, 40]], "area": 1024, "bbox": [8, 8, 32, 32], "iscrowd": 0}));
        let lm = serde_json::json!({"imagePath": name, "imageHeight": h, "imageWidth": w, "shapes": [
            {"label": "carcass", "points": [[8, 8], [40, 8], [40, 40], [8, 40]], "shape_type": "polygon"}]});
        let stem = Path::new(name)
            .file_stem()
            .unwrap()
            .to_string_lossy()
            .to_string();
        std::fs::write(dir.join(format!("{stem}.json")), lm.to_string()).unwrap();
    }
    let coco = serde_json::json!({"images": images, "annotations": anns,
        "categories": [{"id": 1, "name": "carcass"}]});
    let p = coco_path(dir);
    std::fs::write(&p, coco.to_string()).unwrap();
    p
}

/// Beside the folder, not in it: the LabelMe loader reads every `.json` in the folder.
fn coco_path(dir: &Path) -> PathBuf {
    dir.with_extension("coco.json")
}

/// A 1-epoch config on the real set in `dir` (`kind` coco or labelme).
fn config(dir: &Path, kind: &str, n: usize) -> String {
    let real = if kind == "coco" {
        format!(
            "{{ kind = \"coco\", annotations = {:?}, images = {:?} }}",
            coco_path(dir),
            dir
        )
    } else {
        format!("{{ kind = \"labelme\", dir = {:?} }}", dir)
    };
    let f = 1.0 / n as f64;
    let text = format!(
        "name = \"bad\"\n[data]\nreal = {real}\nsplit = [{f}, {f}]\nimage_size = 64\ncrop = 64\n[train]\nepochs = 1\nbatch = 2\nfliplr = 0.0\n"
    );
    let p = dir.join(format!("{kind}.toml"));
    std::fs::write(&p, text).unwrap();
    p.to_string_lossy().into_owned()
}

fn s(p: &Path) -> String {
    p.to_string_lossy().into_owned()
}

/// One row of the matrix: what, the command line, and what its error must mention.
struct Case {
    what: &'static str,
    args: Vec<String>,
    needles: Vec<String>,
}

fn case(what: &'static str, args: &[&str], needles: &[&str]) -> Case {
    Case {
        what,
        args: args.iter().map(|a| a.to_string()).collect(),
        needles: needles.iter().map(|a| a.to_string()).collect(),
    }
}

fn check(cases: &[Case]) {
    for c in cases {
        eprintln!("case: {}", c.what);
        let out = run(&c.args);
        let needles: Vec<&str> = c.needles.iter().map(String::as_str).collect();
        assert_clean_error(&out, &needles);
    }
}

#[test]
fn gray_16bit_rgba_and_exif_images_train_and_predict() {
    let d = tmp("bad-formats");
    let names = ["gray.png", "deep.png", "rgba.png", "exif.jpg"];
    let sized: Vec<(&str, (u32, u32))> = names.iter().map(|n| (*n, write_image(&d, n))).collect();
    assert_eq!(
        image::image_dimensions(d.join("exif.jpg")).unwrap(),
        (48, 64)
    );
    annotate(&d, &sized);
    for kind in ["coco", "labelme"] {
        let rd = d.join(format!("run-{kind}"));
        let out = run(&["--config", &config(&d, kind, 4), "--run-dir", &s(&rd)]);
        assert_success(&out);
        assert!(rd.join("best.bpk").is_file(), "{kind}");
    }
    let out_dir = d.join("pred");
    let ck = d.join("run-coco/best.bpk");
    assert_success(&run(&[
        "predict",
        "--checkpoint",
        &s(&ck),
        "--input",
        &s(&d),
        "--out",
        &s(&out_dir),
    ]));
    let imgs = std::fs::read_to_string(out_dir.join("images.json")).unwrap();
    for n in names {
        assert!(imgs.contains(n), "{n} predicted: {imgs}");
    }
    // The overlay of the EXIF image is upright: 64 wide, 48 high.
    let overlay = std::fs::read_dir(&out_dir)
        .unwrap()
        .filter_map(|e| e.ok().map(|e| e.path()))
        .find(|p| p.to_string_lossy().contains("exif") && p.extension().is_some_and(|e| e == "png"))
        .expect("overlay of exif.jpg");
    assert_eq!(image::image_dimensions(&overlay).unwrap(), (64, 48));
    std::fs::remove_dir_all(&d).unwrap();
    std::fs::remove_file(coco_path(&d)).unwrap();
}

#[test]
fn broken_images_meshes_and_checkpoints_exit_2_naming_the_file() {
    let d = tmp("bad-matrix");
    let mut cases = Vec::new();

    // Images through both real-data loaders: one broken file among good ones.
    let good = write_image(&d, "good.png");
    let png = std::fs::read(d.join("good.png")).unwrap();
    write_image(&d, "plain.jpg");
    let jpg = std::fs::read(d.join("plain.jpg")).unwrap();
    let broken: [(&str, &str, Vec<u8>, &str); 4] = [
        (
            "zero-byte image",
            "empty.png",
            vec![],
            "cannot decode image",
        ),
        (
            "truncated PNG",
            "cut.png",
            png[..png.len() / 2].to_vec(),
            "cannot decode image",
        ),
        (
            "truncated JPEG",
            "cut.jpg",
            jpg[..jpg.len() / 3].to_vec(),
            "cannot decode image",
        ),
        (
            "PNG bytes of garbage",
            "noise.png",
            (0..4000u32).map(|i| (i * 7919 % 251) as u8).collect(),
            "cannot decode image",
        ),
    ];
    for (what, name, bytes, needle) in &broken {
        let sub = d.join(name.replace('.', "_"));
        std::fs::create_dir_all(&sub).unwrap();
        write_image(&sub, "a.png");
        write_image(&sub, "b.png");
        std::fs::write(sub.join(name), bytes).unwrap();
        annotate(&sub, &[("a.png", good), ("b.png", good), (name, good)]);
        for kind in ["coco", "labelme"] {
            let cfg = config(&sub, kind, 3);
            let mut c = case(
                what,
                &["--config", &cfg, "--run-dir", &s(&sub.join("run"))],
                &[name, needle],
            );
            if kind == "labelme" {
                c.what = "(the same through LabelMe)";
            }
            cases.push(c);
        }
    }
    // Missing image, and an image whose size disagrees with its annotation.
    let sub = d.join("missing");
    std::fs::create_dir_all(&sub).unwrap();
    write_image(&sub, "a.png");
    write_image(&sub, "b.png");
    annotate(
        &sub,
        &[("a.png", good), ("b.png", good), ("gone.png", good)],
    );
    for kind in ["coco", "labelme"] {
        let cfg = config(&sub, kind, 3);
        cases.push(case(
            "missing image",
            &["--config", &cfg, "--run-dir", &s(&sub.join("r"))],
            &["gone.png", "does not exist"],
        ));
    }
    let sub = d.join("size");
    std::fs::create_dir_all(&sub).unwrap();
    for n in ["a.png", "b.png", "c.png"] {
        write_image(&sub, n);
    }
    annotate(
        &sub,
        &[("a.png", good), ("b.png", (S, 32)), ("c.png", good)],
    );
    let cfg = config(&sub, "coco", 3);
    cases.push(case(
        "image size disagrees with COCO",
        &["--config", &cfg, "--run-dir", &s(&sub.join("r"))],
        &["b.png", "annotation says 64x32"],
    ));
    let cfg = config(&sub, "labelme", 3);
    cases.push(case(
        "image size disagrees with LabelMe",
        &["--config", &cfg, "--run-dir", &s(&sub.join("r"))],
        &["b.json", "disagrees"],
    ));

    // predict on broken inputs (needs a checkpoint: train the tiny good set once).
    let ok = d.join("ok");
    std::fs::create_dir_all(&ok).unwrap();
    let names = ["a.png", "b.png", "c.png"];
    for n in names {
        write_image(&ok, n);
    }
    annotate(&ok, &names.map(|n| (n, good)));
    let rd = ok.join("run");
    assert_success(&run(&[
        "--config",
        &config(&ok, "coco", 3),
        "--run-dir",
        &s(&rd),
    ]));
    let best = rd.join("best.bpk");
    let last = rd.join("last.bpk");
    let pred = |input: &Path, what: &'static str, needles: &[&str]| {
        case(
            what,
            &[
                "predict",
                "--checkpoint",
                &s(&best),
                "--input",
                &s(input),
                "--out",
                &s(&d.join("p")),
            ],
            needles,
        )
    };
    std::fs::write(d.join("zero.jpg"), b"").unwrap();
    std::fs::write(d.join("cut.jpg"), &jpg[..jpg.len() / 3]).unwrap();
    std::fs::create_dir_all(d.join("no_images")).unwrap();
    cases.push(pred(
        &d.join("zero.jpg"),
        "predict: zero-byte image",
        &["zero.jpg", "cannot decode image"],
    ));
    cases.push(pred(
        &d.join("cut.jpg"),
        "predict: truncated JPEG",
        &["cut.jpg", "cannot decode image"],
    ));
    cases.push(pred(
        &d.join("nope.jpg"),
        "predict: missing input",
        &["nope.jpg", "does not exist"],
    ));
    cases.push(pred(
        &d.join("no_images"),
        "predict: folder without images",
        &["no_images", "no .jpg/.jpeg/.png"],
    ));

    // Meshes through render --carcass.
    let asset = std::fs::read(PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("assets/carcass.glb"))
        .unwrap();
    let at = asset
        .windows(8)
        .position(|w| w == b"\"mode\":4")
        .expect("asset has a triangle primitive");
    let mut lines = asset.clone();
    lines[at + 7] = b'1';
    std::fs::write(d.join("lines.glb"), &lines).unwrap();
    std::fs::write(d.join("empty.glb"), b"").unwrap();
    std::fs::write(d.join("half.glb"), &asset[..asset.len() / 2]).unwrap();
    let render = |mesh: &str, what: &'static str, needles: &[&str]| {
        case(
            what,
            &common::render_one(&s(&d.join(mesh)), &s(&d.join("r"))),
            needles,
        )
    };
    cases.push(render(
        "missing.glb",
        "mesh: missing",
        &["missing.glb", "cannot read carcass mesh"],
    ));
    cases.push(render(
        "empty.glb",
        "mesh: zero bytes",
        &["empty.glb", "not a valid glTF"],
    ));
    cases.push(render(
        "half.glb",
        "mesh: truncated",
        &["half.glb", "not a valid glTF"],
    ));
    cases.push(render(
        "lines.glb",
        "mesh: lines, not triangles",
        &["lines.glb", "only triangles"],
    ));

    // Checkpoints.
    let bytes = std::fs::read(&last).unwrap();
    let write = |name: &str, b: &[u8]| {
        let p = d.join(name);
        std::fs::write(&p, b).unwrap();
        s(&p)
    };
    let cut = write("cut.bpk", &bytes[..bytes.len() * 2 / 3]);
    let header_cut = write("header_cut.bpk", &bytes[..40]);
    let mut huge = b"CHICKTRAIN-CKPT1\n".to_vec();
    huge.extend(u64::MAX.to_le_bytes());
    let huge = write("huge.bpk", &huge);
    let noise: Vec<u8> = (0..5000u32)
        .map(|i| (i.wrapping_mul(2654435761) >> 13) as u8)
        .collect();
    let noise = write("noise.bpk", &noise);
    let ck = Checkpoint::load(&last).unwrap();
    let mut other = Checkpoint {
        header: ck.header.clone(),
        sections: ck.sections.clone(),
    };
    match &mut other.header.model {
        DetectorConfig::Yolo(c) => c.num_classes = 3,
        DetectorConfig::Maskrcnn(c) => c.num_classes = 3,
        DetectorConfig::Mask2former(c) => c.num_classes = 3,
    }
    other.header.category_ids = vec![1, 2, 3];
    other.header.class_names = vec!["a".into(), "b".into(), "c".into()];
    let three = d.join("three.bpk");
    other.save(&three).unwrap();
    let mut flipped = Checkpoint {
        header: ck.header.clone(),
        sections: ck.sections.clone(),
    };
    for (name, data) in flipped.sections.iter_mut() {
        if name == "ema" {
            let n = data.len();
            for b in &mut data[n / 3..n / 3 + 64] {
                *b = !*b;
            }
            data.truncate(n - 100);
        }
    }
    let flipped_p = d.join("flipped.bpk");
    flipped.save(&flipped_p).unwrap();
    // (what, file, what eval's error says, what predict's says); both name the file.
    let three = s(&three);
    let flipped = s(&flipped_p);
    let rows: [(&'static str, &str, &str, &str); 6] = [
        ("checkpoint: truncated", &cut, "truncated", "truncated"),
        (
            "checkpoint: cut inside the header",
            &header_cut,
            "truncated",
            "truncated",
        ),
        (
            "checkpoint: header length 2^64-1",
            &huge,
            "truncated",
            "truncated",
        ),
        (
            "checkpoint: random bytes",
            &noise,
            "not a chicktrain checkpoint",
            "not a chicktrain checkpoint",
        ),
        (
            "checkpoint: another class count",
            &three,
            "differ from the checkpoint's",
            "weights do not fit",
        ),
        (
            "checkpoint: corrupt weights",
            &flipped,
            "corrupt \"ema\" weights",
            "corrupt \"ema\" weights",
        ),
    ];
    for (what, f, eval_says, predict_says) in rows {
        let name = Path::new(f)
            .file_name()
            .unwrap()
            .to_string_lossy()
            .to_string();
        cases.push(Case {
            what,
            args: vec!["eval".into(), "--checkpoint".into(), f.to_string()],
            needles: vec![name.clone(), eval_says.into()],
        });
        let img = s(&ok.join("a.png"));
        let out = s(&d.join("p"));
        cases.push(Case {
            what,
            args: ["predict", "--checkpoint", f, "--input", &img, "--out", &out]
                .map(String::from)
                .to_vec(),
            needles: vec![name, predict_says.into()],
        });
    }
    // --resume with a broken last.bpk, a best.bpk (no optimiser state) and a config
    // whose model differs from the checkpoint's.
    let cfg = config(&ok, "coco", 3);
    let resume = |what: &'static str, file: &[u8], sets: &[&str], needles: &[&str]| {
        let rdir = d.join(what.replace([' ', ':', '\''], "_"));
        std::fs::create_dir_all(&rdir).unwrap();
        std::fs::write(rdir.join("last.bpk"), file).unwrap();
        let mut a = vec![
            "--config".to_string(),
            cfg.clone(),
            "--run-dir".into(),
            s(&rdir),
            "--resume".into(),
            "--set".into(),
            "train.epochs=2".into(),
        ];
        for x in sets {
            a.push("--set".into());
            a.push(x.to_string());
        }
        Case {
            what,
            args: a,
            needles: needles.iter().map(|n| n.to_string()).collect(),
        }
    };
    cases.push(resume(
        "resume: truncated last.bpk",
        &bytes[..bytes.len() / 2],
        &[],
        &["last.bpk", "truncated"],
    ));
    cases.push(resume(
        "resume: best.bpk as last.bpk",
        &std::fs::read(&best).unwrap(),
        &[],
        &["last.bpk", "has no \"model\" weights"],
    ));
    cases.push(resume(
        "resume: config model differs",
        &bytes,
        &["model.scale=\"s\""],
        &["--resume", "last.bpk", "differs from the config"],
    ));
    cases.push(resume(
        "resume: checkpoint of another class count",
        &std::fs::read(&three).unwrap(),
        &[],
        &["--resume", "last.bpk", "it has 3 classes, the data has 1"],
    ));

    eprintln!("{} cases", cases.len());
    assert!(cases.len() >= 30);
    check(&cases);
    std::fs::remove_dir_all(&d).unwrap();
}
