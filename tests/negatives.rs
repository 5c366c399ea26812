//! Issue 38 part 2: the negatives knob (`[data.negatives]`). A share of carcass-free
//! renders and of renders with distractors, each a per-image coin from its own stream:
//! the images the coin skips stay byte-identical to the renders without the knob, the
//! ones it picks lose every carcass (empty) or gain non-carcass objects (distractors),
//! and the render cache keeps the two apart. The clutter share replaces the images its
//! coin picks by dead-leaves pictures without labels. Tiny renders (64 px), no files.

use chicktrain::config::{self, Negatives, Randomize, SHIPPED};
use chicktrain::render::{cache, render_sample, RenderOptions};

fn training_opts(neg: Negatives) -> RenderOptions {
    let mut o = RenderOptions::synthetic(64);
    o.carcasses = [2, 4];
    o.randomize = Randomize::TRAINING;
    o.negatives = neg;
    o
}

#[test]
fn empty_share_removes_every_carcass_of_the_picked_images_only() {
    let off = training_opts(Negatives::default());
    let half = training_opts(Negatives {
        empty: 0.5,
        ..Negatives::default()
    });
    let (mut picked, n) = (0, 8);
    for i in 0..n {
        let a = render_sample(&off, 7, i).unwrap();
        let b = render_sample(&half, 7, i).unwrap();
        assert!(
            !a.instances.is_empty(),
            "image {i} of the plain set is empty"
        );
        if b.instances.is_empty() {
            picked += 1;
            assert!(b.ids.iter().all(|&v| v == 0), "image {i}: ids left");
            assert_ne!(a.image, b.image, "image {i}");
        } else {
            assert_eq!(a.image, b.image, "image {i} changed without being picked");
            assert_eq!(a.ids, b.ids);
        }
    }
    assert!(picked > 0 && picked < n, "{picked}/{n} picked at share 0.5");
    let all = training_opts(Negatives {
        empty: 1.0,
        ..Negatives::default()
    });
    for i in 0..3 {
        assert!(render_sample(&all, 7, i).unwrap().instances.is_empty());
    }
}

#[test]
fn distractor_share_adds_objects_but_never_labels_them() {
    let off = training_opts(Negatives::default());
    let every = training_opts(Negatives {
        distractors: 1.0,
        ..Negatives::default()
    });
    for i in 0..3 {
        let a = render_sample(&off, 9, i).unwrap();
        let b = render_sample(&every, 9, i).unwrap();
        // At least one object in every picked image (the group's range starts at none).
        assert_ne!(a.image, b.image, "image {i}: no distractor drawn");
        // Objects occlude carcasses but are never an instance of their own.
        assert!(b.instances.len() <= a.instances.len(), "image {i}");
        let ids: std::collections::BTreeSet<u16> = b.instances.iter().map(|l| l.id).collect();
        assert!(
            b.ids.iter().all(|v| *v == 0 || ids.contains(v)),
            "image {i}"
        );
    }
}

#[test]
fn cache_key_is_unchanged_while_off_and_differs_when_on() {
    let off = training_opts(Negatives::default());
    let on = training_opts(Negatives {
        empty: 0.1,
        ..Negatives::default()
    });
    let json = serde_json::to_string(&off).unwrap();
    assert!(!json.contains("negatives"), "{json}");
    assert_ne!(
        cache::cache_key(&off, 0).unwrap(),
        cache::cache_key(&on, 0).unwrap()
    );
    // A clutter share of 0 is not written, so the caches of configs from before the
    // clutter share stay valid; a share > 0 is a different key.
    let json = serde_json::to_string(&on).unwrap();
    assert!(!json.contains("clutter"), "{json}");
    let cluttered = training_opts(Negatives {
        clutter: 0.1,
        ..on.negatives
    });
    assert_ne!(
        cache::cache_key(&on, 0).unwrap(),
        cache::cache_key(&cluttered, 0).unwrap()
    );
}

#[test]
fn clutter_share_replaces_the_picked_images_by_unlabelled_pictures_only() {
    let base = Negatives {
        empty: 0.1,
        distractors: 0.5,
        ..Negatives::default()
    };
    let plain = training_opts(base);
    let half = training_opts(Negatives {
        clutter: 0.5,
        ..base
    });
    let (mut picked, n) = (0, 10);
    for i in 0..n {
        let a = render_sample(&plain, 5, i).unwrap();
        let b = render_sample(&half, 5, i).unwrap();
        if a.image == b.image {
            assert_eq!(a.ids, b.ids, "image {i}");
            assert_eq!(a.instances.len(), b.instances.len(), "image {i}");
            continue;
        }
        picked += 1;
        assert!(b.instances.is_empty() && b.placed == 0, "image {i}");
        assert!(b.ids.iter().all(|&v| v == 0), "image {i}: ids left");
        assert_eq!(b.image.dimensions(), a.image.dimensions());
    }
    assert!(picked > 0 && picked < n, "{picked}/{n} picked at share 0.5");
    let all = training_opts(Negatives {
        clutter: 1.0,
        ..base
    });
    let (x, y) = (
        render_sample(&all, 5, 0).unwrap(),
        render_sample(&all, 5, 1).unwrap(),
    );
    assert!(x.instances.is_empty() && y.instances.is_empty());
    assert_ne!(x.image, y.image, "every picture the same");
}

#[test]
fn config_table_reaches_the_data_config_and_bad_shares_name_the_key() {
    let cfg = config::parse(
        SHIPPED[0].1,
        "q",
        &[
            "data.negatives.empty=0.1".into(),
            "data.negatives.distractors=0.5".into(),
            "data.negatives.clutter=0.2".into(),
        ],
    )
    .unwrap();
    assert_eq!(cfg.data.negatives.empty, 0.1);
    assert_eq!(cfg.data.negatives.distractors, 0.5);
    assert_eq!(cfg.data.negatives.clutter, 0.2);
    let bad = config::parse(SHIPPED[0].1, "q", &["data.negatives.empty=1.5".into()])
        .and_then(|c| c.data.validate().map(|_| c));
    let e = format!("{:#}", bad.err().expect("a share of 1.5 must be refused"));
    assert!(e.contains("data.negatives.empty"), "{e}");
    let typo = config::parse(SHIPPED[0].1, "q", &["data.negatives.emtpy=0.1".into()]);
    assert!(typo.is_err());
}
