//! YOLO-seg datasets in (`data.real = { kind = "yolo", yaml = … }`) and a dataset's own
//! split (issue 39): ultralytics' folder layout and Roboflow's, malformed label lines and
//! missing keys or folders failing with the file (and line) named, the round trip
//! COCO per split → `convert coco2yolo` → YAML giving the same instances and split, and a
//! smoke training from the YAML.
//!
//! Every dataset here is made by the test in a temp folder: tiny PNGs, hand-written
//! labels and COCO files.

use std::path::{Path, PathBuf};

use chicktrain::annotations::coco::{CocoDataset, Segmentation};
use chicktrain::annotations::rle::Rle;
use chicktrain::annotations::split::Split;
use chicktrain::annotations::yolo;
use chicktrain::config::{self, Config};
use chicktrain::data::dataset::RealSet;

mod common;
use common::{assert_clean_error, assert_success, run, tmp};

fn png(path: &Path, w: u32, h: u32) {
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    image::RgbImage::from_pixel(w, h, image::Rgb([120, 90, 60]))
        .save(path)
        .unwrap();
}

fn write(path: &Path, text: &str) {
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    std::fs::write(path, text).unwrap();
}

/// `convert coco2yolo` of the COCO files `splits` into the folder `out`.
fn coco2yolo(splits: &[&Path], out: &Path) -> std::process::Output {
    let mut args = vec!["convert", "coco2yolo"];
    args.extend(splits.iter().map(|p| s(p)));
    args.extend(["--out", s(out)]);
    run(&args)
}

/// `train --config quickstart` with a `--set` of each of `sets`.
fn train_quickstart(sets: &[&str]) -> std::process::Output {
    let mut args = vec!["train", "--config", "quickstart"];
    for set in sets {
        args.extend(["--set", set]);
    }
    run(&args)
}

/// `yaml` written to `path`, loaded.
fn write_and_load(path: &Path, yaml: &str) -> yolo::YoloDataset {
    write(path, yaml);
    yolo::load(path).unwrap()
}

/// The error of loading `ds/data.yaml` under `d` written as `yaml`.
fn load_err(d: &Path, yaml: &str) -> String {
    write(&d.join("ds/data.yaml"), yaml);
    format!("{:#}", yolo::load(&d.join("ds/data.yaml")).unwrap_err())
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// A config on shipped `quickstart` reading the real set from `sets` (e.g.
/// `data.real.kind="yolo"`), render cache in `dir`.
fn config_with(dir: &Path, sets: &[String]) -> Config {
    let mut ov = vec![
        format!("data.cache=\"{}\"", dir.join("cache").display()),
        "data.synthetic=0".to_string(),
    ];
    ov.extend(sets.iter().cloned());
    config::load("quickstart", &ov).unwrap()
}

fn yolo_config(dir: &Path, yaml: &Path) -> Config {
    config_with(
        dir,
        &[
            "data.real.kind=\"yolo\"".into(),
            format!("data.real.yaml=\"{}\"", yaml.display()),
        ],
    )
}

/// The base name of image `id`'s file.
fn base(ds: &CocoDataset, id: u64) -> String {
    let f = &ds.image(id).unwrap().file_name;
    Path::new(f)
        .file_name()
        .unwrap()
        .to_string_lossy()
        .into_owned()
}

fn names(ds: &CocoDataset, ids: &[u64]) -> Vec<String> {
    let mut v: Vec<String> = ids.iter().map(|&i| base(ds, i)).collect();
    v.sort();
    v
}

/// ultralytics' own layout: `images/{train,val,test}`, `labels/…`, names as a map.
#[test]
fn reads_the_ultralytics_layout_with_its_own_split() {
    let d = tmp("yolo-layout");
    png(&d.join("ds/images/train/a.png"), 100, 50);
    png(&d.join("ds/images/train/sub/b.png"), 40, 40);
    png(&d.join("ds/images/val/c.png"), 64, 32);
    png(&d.join("ds/images/test/e.png"), 32, 32);
    write(&d.join("ds/images/train/notes.md"), "not an image");
    write(
        &d.join("ds/labels/train/a.txt"),
        "0 0.1 0.2 0.6 0.2 0.6 0.8\n1 0.5 0.5 0.9 0.5 0.9 0.9 0.5 0.9\n",
    );
    // b has no label file: an image without instances. c's is empty.
    write(&d.join("ds/labels/val/c.txt"), "");
    write(&d.join("ds/labels/test/e.txt"), "1 0 0 1 0 1 1\n");
    let y = write_and_load(&d.join("ds/data.yaml"), "path: .\ntrain: images/train\nval: images/val\ntest: images/test\nnames:\n  0: carcass\n  1: wing\n");
    let ds = &y.coco;
    let cats: Vec<(u64, &str)> = ds
        .categories
        .iter()
        .map(|c| (c.id, c.name.as_str()))
        .collect();
    assert_eq!(cats, [(1, "carcass"), (2, "wing")]);
    assert_eq!(ds.images.len(), 4);
    let own = y.own_split.clone().expect("train, val and test differ");
    assert_eq!(names(ds, &own.train), ["a.png", "b.png"]);
    assert_eq!(names(ds, &own.val), ["c.png"]);
    assert_eq!(names(ds, &own.test), ["e.png"]);
    let a = ds
        .images
        .iter()
        .find(|i| i.file_name.ends_with("a.png"))
        .unwrap();
    assert_eq!((a.width, a.height), (100, 50));
    let anns: Vec<_> = ds
        .annotations
        .iter()
        .filter(|x| x.image_id == a.id)
        .collect();
    assert_eq!(anns.len(), 2);
    assert_eq!(anns[0].category_id, 1);
    assert_eq!(
        anns[0].segmentation,
        Segmentation::Polygons(vec![vec![10.0, 10.0, 60.0, 10.0, 60.0, 40.0]])
    );
    assert_eq!(anns[1].category_id, 2);
    // pycocotools' area of the 40 × 20 px square at (50, 25).
    assert_eq!(anns[1].bbox, [50.0, 25.0, 40.0, 20.0]);
    assert_eq!(ds.annotations.len(), 3);

    // Through the config: the run keeps the yaml's split, whatever data.split says.
    let cfg = yolo_config(&d, &d.join("ds/data.yaml"));
    let real = RealSet::load(&cfg.data, cfg.seed).unwrap();
    assert_eq!(real.class_names(), ["carcass", "wing"]);
    let split = Split::for_training(
        &real.ids(),
        real.own_split.as_ref(),
        cfg.data.split,
        cfg.seed,
        None,
    )
    .unwrap();
    assert_eq!(names(&real.gt, &split.train), ["a.png", "b.png"]);
    assert_eq!(names(&real.gt, &split.test), ["e.png"]);
    let sample = real.sample(split.test[0], 64).unwrap();
    assert_eq!(sample.instances.len(), 1);
    assert_eq!(sample.instances[0].class, 1);
    std::fs::remove_dir_all(&d).unwrap();
}

/// Roboflow's export: no `path`, `../train/images`, a flow list of names, extra keys; and
/// a `.txt` list of images.
#[test]
fn reads_roboflow_exports_and_image_lists() {
    let d = tmp("yolo-roboflow");
    for (part, img) in [("train", "a"), ("valid", "b"), ("test", "c")] {
        png(&d.join(format!("rf/{part}/images/{img}.jpg")), 48, 48);
        write(
            &d.join(format!("rf/{part}/labels/{img}.txt")),
            "0 0.25 0.25 0.75 0.25 0.5 0.75\n",
        );
    }
    let y = write_and_load(&d.join("rf/data.yaml"), "train: ../train/images\nval: ../valid/images\ntest: ../test/images\n\nnc: 1\nnames: ['carcass']\n\nroboflow:\n  workspace: farm\n  version: 2\n");
    let own = y.own_split.unwrap();
    assert_eq!(names(&y.coco, &own.val), ["b.jpg"]);
    assert_eq!(y.coco.annotations.len(), 3);

    // A .txt list: `./` relative to the list's folder.
    write(
        &d.join("rf/train.txt"),
        "./train/images/a.jpg\n\n./test/images/c.jpg\n",
    );
    let y = write_and_load(
        &d.join("rf/list.yaml"),
        "train: train.txt\nval: [valid/images]\nnames: [carcass]\n",
    );
    let own = y.own_split.unwrap();
    assert_eq!(names(&y.coco, &own.train), ["a.jpg", "c.jpg"]);
    assert!(own.test.is_empty());
    // No test part: a run cannot take its final scores, and says why.
    let cfg = yolo_config(&d, &d.join("rf/list.yaml"));
    let real = RealSet::load(&cfg.data, cfg.seed).unwrap();
    let e = Split::for_training(&real.ids(), real.own_split.as_ref(), [0.2, 0.2], 0, None)
        .unwrap_err()
        .to_string();
    assert!(e.contains("no test images"), "{e}");
    std::fs::remove_dir_all(&d).unwrap();
}

/// The data.yaml and one image with label `label`, under `d/bad`.
fn one_image_set(d: &Path, label: &str) -> PathBuf {
    png(&d.join("bad/images/t/a.png"), 20, 20);
    png(&d.join("bad/images/v/b.png"), 20, 20);
    write(&d.join("bad/labels/t/a.txt"), label);
    let y = d.join("bad/data.yaml");
    write(&y, "train: images/t\nval: images/v\nnames: [carcass]\n");
    y
}

#[test]
fn malformed_labels_name_the_file_and_line() {
    let d = tmp("yolo-bad-labels");
    let good = "0 0.1 0.1 0.9 0.1 0.9 0.9\n";
    for (line, needle) in [
        ("0 0.1 0.1 0.9 0.1 0.9\n", "odd number of coordinates"),
        ("0 0.1 0.1 0.9 0.1\n", "is a box"),
        ("0 0.1 0.1 0.9 0.1 0.9 0.9 0.5\n", "odd number"),
        ("0 0.1 0.1\n", "at least 3"),
        ("0 0.1 zero 0.9 0.1 0.9 0.9\n", "\"zero\" is not a number"),
        ("1 0.1 0.1 0.9 0.1 0.9 0.9\n", "class id 1 is out of range"),
        ("0 0.1 0.1 9 0.1 0.9 0.9\n", "outside [0, 1]"),
        ("0 0.1 0.1 0.9 -1e300 0.9 0.9\n", "outside [0, 1]"),
        ("0 0.1 0.1 0.9 0.1 0.9 inf\n", "not a number"),
    ] {
        let y = one_image_set(&d, &format!("{good}{line}"));
        let e = format!("{:#}", yolo::load(&y).unwrap_err());
        let file = d.join("bad/labels/t/a.txt");
        assert!(
            e.contains(&format!("{}:2", file.display())),
            "{line:?}: {e}"
        );
        assert!(e.contains(needle), "{line:?}: {e}");
    }
    // The CLI: exit 2, the file and line named, no panic.
    let y = one_image_set(&d, "0 0.1 0.1 0.9\n");
    let out = run(&[
        "train",
        "--config",
        "quickstart",
        "--smoke",
        "--run-dir",
        s(&d.join("run")),
        "--set",
        &format!("data.cache=\"{}\"", d.join("cache").display()),
        "--set",
        "data.real.kind=\"yolo\"",
        "--set",
        &format!("data.real.yaml=\"{}\"", y.display()),
    ]);
    assert_clean_error(&out, &["a.txt:1", "odd number of coordinates"]);
    std::fs::remove_dir_all(&d).unwrap();
}

#[test]
fn missing_keys_folders_and_overlaps_are_clear_errors() {
    let d = tmp("yolo-bad-yaml");
    png(&d.join("ds/images/t/a.png"), 20, 20);
    png(&d.join("ds/images/v/b.png"), 20, 20);
    for (yaml, needles) in [
        (
            "val: images/v\nnames: [c]\n",
            vec!["data.yaml", "has no `train`"],
        ),
        ("train: images/t\nnames: [c]\n", vec!["has no `val`"]),
        (
            "train: images/t\nval: images/v\n",
            vec!["neither `names` nor `nc`"],
        ),
        (
            "train: images/t\nval: images/gone\nnames: [c]\n",
            vec!["`val` of", "images/gone does not exist"],
        ),
        (
            "train: images/t\nval: list.txt\nnames: [c]\n",
            vec!["list.txt does not exist"],
        ),
        (
            "train: [images/t, images/v]\nval: images/v\nnames: [c]\n",
            vec!["`train` and `val` share 1 images", "b.png"],
        ),
        (
            "train: images/t\nval: images/v\nnames: [c\n",
            vec!["invalid YAML at line"],
        ),
    ] {
        let e = load_err(&d, yaml);
        for n in needles {
            assert!(e.contains(n), "{yaml:?}: {e}");
        }
    }
    // An empty folder, a list naming a missing image.
    std::fs::create_dir_all(d.join("ds/images/empty")).unwrap();
    let e = load_err(&d, "train: images/empty\nval: images/v\nnames: [c]\n");
    assert!(e.contains("no images") && e.contains("images/empty"), "{e}");
    write(&d.join("ds/l.txt"), "./images/t/a.png\n./images/t/zz.png\n");
    let e = load_err(&d, "train: l.txt\nval: images/v\nnames: [c]\n");
    assert!(e.contains("l.txt:2") && e.contains("zz.png"), "{e}");
    // A corrupt image: named.
    write(&d.join("ds/images/v/b.png"), "not a png");
    let e = load_err(&d, "train: images/t\nval: images/v\nnames: [c]\n");
    assert!(e.contains("b.png"), "{e}");
    // The config: kind = "yolo" without yaml, a yaml that is not there.
    let out = train_quickstart(&["data.real.kind=\"yolo\""]);
    assert_clean_error(&out, &["data.real.yaml"]);
    let out = train_quickstart(&[
        "data.real.kind=\"yolo\"",
        "data.real.yaml=\"nowhere/data.yaml\"",
    ]);
    assert_clean_error(&out, &["nowhere/data.yaml", "does not exist"]);
    std::fs::remove_dir_all(&d).unwrap();
}

/// A tiny COCO set split into three files beside its images: 3 train / 2 val / 1 test,
/// several sizes, a two-part instance, a crowd, two categories.
fn coco_split_set(dir: &Path) -> [PathBuf; 3] {
    let sizes = [(96, 64), (64, 64), (80, 120), (64, 96), (128, 64), (72, 72)];
    for (i, (w, h)) in sizes.iter().enumerate() {
        png(&dir.join(format!("img{i}.png")), *w, *h);
    }
    let cats = r#"[{"id": 4, "name": "carcass"}, {"id": 9, "name": "wing"}]"#;
    let image = |i: usize| {
        let (w, h) = sizes[i];
        format!(
            r#"{{"id": {}, "file_name": "img{i}.png", "width": {w}, "height": {h}}}"#,
            10 + i
        )
    };
    let ann = |id: usize, img: usize, cat: u64, seg: &str, crowd: u8| {
        format!(
            r#"{{"id": {id}, "image_id": {}, "category_id": {cat}, "segmentation": {seg}, "area": 100, "bbox": [1, 1, 10, 10], "iscrowd": {crowd}}}"#,
            10 + img
        )
    };
    let tri = |x: f64, y: f64, r: f64| {
        format!(
            "[[{x}, {y}, {}, {}, {}, {}, {}, {}, {}, {}]]",
            x + r,
            y + 0.3 * r,
            x + 1.2 * r,
            y + r,
            x + 0.4 * r,
            y + 1.3 * r,
            x - 0.2 * r,
            y + 0.7 * r
        )
    };
    let two_part = "[[5, 5, 25, 5, 25, 25, 5, 25], [40, 30, 60, 30, 50, 50]]";
    let crowd = r#"{"size": [96, 64], "counts": [100, 20, 6024]}"#;
    let files = [
        (
            "train",
            vec![0, 1, 2],
            vec![
                ann(1, 0, 4, &tri(10.5, 8.25, 30.0), 0),
                ann(2, 0, 9, &tri(50.0, 20.0, 25.0), 0),
                ann(3, 1, 4, two_part, 0),
                ann(4, 2, 4, &tri(12.0, 40.0, 40.0), 0),
            ],
        ),
        (
            "val",
            vec![3, 4],
            vec![
                ann(5, 3, 9, &tri(8.0, 8.0, 35.0), 0),
                ann(6, 3, 4, crowd, 1),
            ],
        ),
        (
            "test",
            vec![5],
            vec![ann(7, 5, 4, &tri(20.0, 15.0, 33.3), 0)],
        ),
    ];
    files.map(|(name, imgs, anns)| {
        let imgs: Vec<String> = imgs.into_iter().map(image).collect();
        let p = dir.join(format!("{name}.json"));
        write(
            &p,
            &format!(
                r#"{{"images": [{}], "annotations": [{}], "categories": {cats}}}"#,
                imgs.join(", "),
                anns.join(", ")
            ),
        );
        p
    })
}

/// Per image base name: (category name, mask) of its non-crowd instances, in file order.
fn instances(real: &RealSet) -> Vec<(String, Vec<(String, Rle)>)> {
    let gt = &real.gt;
    let mut out: Vec<_> = gt
        .images
        .iter()
        .map(|im| {
            let inst = gt
                .annotations
                .iter()
                .filter(|a| a.image_id == im.id && a.iscrowd == 0)
                .map(|a| {
                    let cat = gt
                        .categories
                        .iter()
                        .find(|c| c.id == a.category_id)
                        .unwrap();
                    (
                        cat.name.clone(),
                        a.segmentation.to_rle(im.height, im.width).unwrap(),
                    )
                })
                .collect();
            (base(gt, im.id), inst)
        })
        .collect();
    out.sort_by(|a, b| a.0.cmp(&b.0));
    out
}

fn iou(a: &Rle, b: &Rle) -> f64 {
    let (a, b) = (a.decode(), b.decode());
    let (mut inter, mut union) = (0u64, 0u64);
    for (x, y) in a.data.iter().zip(&b.data) {
        inter += (*x != 0 && *y != 0) as u64;
        union += (*x != 0 || *y != 0) as u64;
    }
    inter as f64 / union.max(1) as f64
}

/// COCO per split → `convert coco2yolo` → `kind = "yolo"`: the same images, split,
/// classes and instances. Polygons agree within `%g`'s 6 significant digits; masks are
/// equal except the two-part instance, which ultralytics' converter joins into one
/// outline (IoU ≥ 0.99 for every mask, checked).
#[test]
fn coco_per_split_round_trips_through_coco2yolo() {
    let d = tmp("yolo-roundtrip");
    let [train, val, test] = coco_split_set(&d.join("coco"));
    assert_success(&coco2yolo(&[&train, &val, &test], &d.join("y")));
    assert!(d.join("y/images/val/img3.png").is_file());
    assert!(d.join("y/labels/test/img5.txt").is_file());

    let coco_cfg = config_with(
        &d,
        &[
            "data.real.kind=\"coco\"".into(),
            format!("data.real.train=\"{}\"", train.display()),
            format!("data.real.val=\"{}\"", val.display()),
            format!("data.real.test=\"{}\"", test.display()),
        ],
    );
    let yolo_cfg = yolo_config(&d, &d.join("y/data.yaml"));
    let coco = RealSet::load(&coco_cfg.data, 0).unwrap();
    let yolo = RealSet::load(&yolo_cfg.data, 0).unwrap();
    assert_eq!(coco.class_names(), yolo.class_names());

    // The same split, the files' own (not the 20/20/60 draw).
    let split_of = |r: &RealSet| {
        let s = Split::for_training(&r.ids(), r.own_split.as_ref(), [0.2, 0.2], 0, None).unwrap();
        [
            names(&r.gt, &s.train),
            names(&r.gt, &s.val),
            names(&r.gt, &s.test),
        ]
    };
    assert_eq!(split_of(&coco), split_of(&yolo));
    assert_eq!(split_of(&yolo)[1], ["img3.png", "img4.png"]);

    // The same instances.
    let (a, b) = (instances(&coco), instances(&yolo));
    assert_eq!(a.len(), 6);
    for ((name_a, ia), (name_b, ib)) in a.iter().zip(&b) {
        assert_eq!(name_a, name_b);
        assert_eq!(ia.len(), ib.len(), "{name_a}");
        for ((ca, ma), (cb, mb)) in ia.iter().zip(ib) {
            assert_eq!(ca, cb, "{name_a}");
            let v = iou(ma, mb);
            assert!(v >= 0.99, "{name_a}: mask IoU {v}");
        }
    }
    // Not asserted: pixel-equal masks. The text format keeps 6 significant digits, so a
    // vertex moves by up to ~5e-6 of the image and a boundary pixel can flip when the
    // polygon is rasterised again (3 of these 6 come back pixel-equal).
    // Single-part polygons: within the text format's quantisation (%g: 6 digits).
    let poly = |r: &RealSet, file: &str| -> Vec<f64> {
        let im =
            r.gt.images
                .iter()
                .find(|i| i.file_name.ends_with(file))
                .unwrap();
        let a =
            r.gt.annotations
                .iter()
                .find(|a| a.image_id == im.id)
                .unwrap();
        match &a.segmentation {
            Segmentation::Polygons(p) => p[0].clone(),
            _ => unreachable!(),
        }
    };
    let (pa, pb) = (poly(&coco, "img0.png"), poly(&yolo, "img0.png"));
    assert_eq!(pa.len(), pb.len());
    for (x, y) in pa.iter().zip(&pb) {
        assert!((x - y).abs() <= 96.0 * 5e-6, "{x} vs {y}");
    }

    // One file, no split: train and val are the same images, and the run draws its own.
    let all = d.join("coco/all.json");
    let mut ds = CocoDataset::load(&train).unwrap();
    ds.images.retain(|i| i.id != 11); // keep it to the single-polygon instances
    ds.annotations.retain(|a| a.image_id != 11);
    ds.save(&all).unwrap();
    assert_success(&coco2yolo(&[&all], &d.join("y1")));
    let y1 = yolo::load(&d.join("y1/data.yaml")).unwrap();
    assert!(y1.own_split.is_none());
    assert_eq!(y1.coco.images.len(), 2);
    std::fs::remove_dir_all(&d).unwrap();
}

/// A 2-epoch `--smoke` YOLO run trained from the data.yaml that `convert coco2yolo`
/// wrote: it keeps the dataset's split and writes its test scores.
#[test]
fn trains_from_a_converted_yaml() {
    let d = tmp("yolo-train");
    let [train, val, test] = coco_split_set(&d.join("coco"));
    assert_success(&coco2yolo(&[&train, &val, &test], &d.join("y")));
    let cfg = yolo_config(&d, &d.join("y/data.yaml"));
    let opts = chicktrain::train::trainer::TrainOptions {
        run_dir: Some(d.join("run")),
        smoke: true,
        quiet: true,
        ..Default::default()
    };
    let sum = chicktrain::train::trainer::train(cfg, &opts).unwrap();
    assert!(!sum.proxy);
    assert_eq!(sum.test_images, 1);
    let split: Split =
        serde_json::from_str(&std::fs::read_to_string(d.join("run/split.json")).unwrap()).unwrap();
    assert_eq!(
        (split.train.len(), split.val.len(), split.test.len()),
        (3, 2, 1)
    );
    assert!(d.join("run/test.json").is_file());
    std::fs::remove_dir_all(&d).unwrap();
}
