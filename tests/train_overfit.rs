//! The model must *learn* through the training data path: one small rendered scene
//! (96 px, 2–3 carcasses), batched by the trainer's own `collate`, overfit with AdamW
//! until the eval-mode model scores segm AP50 ≥ 0.9 on that scene with the in-tree COCO
//! evaluator (conf 0.001, NMS 0.7, masks as RLE — the per-epoch validation path).

use burn::module::Module;
use burn::optim::{AdamWConfig, GradientsParams};
use burn::tensor::{Device, Tensor, TensorData};
use chicktrain::annotations::coco::{CocoCategory, CocoDataset, CocoImage};
use chicktrain::data::batch::collate;
use chicktrain::data::dataset::{from_rendered, render_options};
use chicktrain::eval::{evaluate, IouType};
use chicktrain::infer::detector::{VAL_CONF, VAL_IOU, VAL_MAX_DET};
use chicktrain::infer::validate::to_coco;
use chicktrain::model::yolo::loss::{yolo_loss, LossWeights};
use chicktrain::model::yolo::postprocess::postprocess;
use chicktrain::model::yolo::{Scale, YoloSegConfig};
use chicktrain::render::export::annotations;
use chicktrain::render::render_sample;

const SIZE: u32 = 96;
const STEPS: usize = 300;
/// Forward/backward passes without updates so BatchNorm's running statistics (momentum
/// 0.03) catch up with the final weights before the eval-mode check.
const CALIB: usize = 60;

#[test]
fn overfits_one_rendered_scene_to_segm_ap50_0_9() {
    let t0 = std::time::Instant::now();
    let mut opts = render_options(false, SIZE);
    opts.carcasses = [2, 3];
    // A close camera, so the carcasses span ~40 px of the 96 px frame rather than ~20:
    // the test is about learning through the data path, not about tiny objects.
    opts.camera_height = [0.6, 0.6];
    opts.fov_deg = [40.0, 40.0];
    let rendered = render_sample(&opts, 3, 0).unwrap();
    let sample = from_rendered(&rendered);
    assert!(!sample.instances.is_empty());
    let gt = CocoDataset {
        info: None,
        licenses: None,
        images: vec![CocoImage {
            id: 1,
            file_name: "scene.jpg".into(),
            width: SIZE,
            height: SIZE,
            extra: Default::default(),
        }],
        annotations: annotations(&rendered.ids, SIZE, SIZE, &rendered.instances, 1, 1),
        categories: vec![CocoCategory {
            id: 1,
            name: "carcass".into(),
            extra: Default::default(),
        }],
    };
    let batch = collate(&[sample.clone(), sample]).unwrap();

    let dev = Device::flex();
    dev.seed(7);
    let ad = dev.clone().autodiff();
    let mut model = YoloSegConfig::new(Scale::N, 1)
        .with_input_size(SIZE as usize)
        .with_width_mult(0.5)
        .with_num_masks(8)
        .init(&ad);
    let mut optim = AdamWConfig::new().with_weight_decay(0.0).init();
    let x = Tensor::<4>::from_data(TensorData::new(batch.pixels.clone(), batch.dims), &ad);
    let w = LossWeights::default();
    for step in 0..STEPS + CALIB {
        let out = model.forward(x.clone());
        let loss = yolo_loss(&out, &batch.targets, &w);
        let grads = GradientsParams::from_grads(loss.total.backward(), &model);
        if step < STEPS {
            model = optim.step(2e-3, model, grads);
        }
    }

    let eval = model.valid();
    let xe = Tensor::<4>::from_data(
        TensorData::new(
            batch.pixels[..3 * (SIZE * SIZE) as usize].to_vec(),
            [1, 3, SIZE as usize, SIZE as usize],
        ),
        &dev,
    );
    let raw = postprocess(&eval.forward(xe), VAL_CONF, VAL_IOU, VAL_MAX_DET);
    let dets: Vec<_> = raw[0]
        .iter()
        .map(|d| to_coco(d, 1, &[1], SIZE, (SIZE, SIZE)))
        .collect();
    let segm = evaluate(&gt, &dets, IouType::Segm).unwrap();
    let bbox = evaluate(&gt, &dets, IouType::Bbox).unwrap();
    eprintln!(
        "{} GT, {} dets: segm AP50 {:.3} AP {:.3}, bbox AP50 {:.3}; {:.1} s",
        gt.annotations.len(),
        dets.len(),
        segm.stats[1],
        segm.stats[0],
        bbox.stats[1],
        t0.elapsed().as_secs_f64()
    );
    assert!(segm.stats[1] >= 0.9, "segm AP50 {} < 0.9", segm.stats[1]);
}
