//! RoIAlign timing, ignored by default (a measurement, not a check). Whole-model timings
//! are `chicktrain bench models` (e.g. `--variants mrcnn-r50,mrcnn-r50-paper --sizes 512`).

use burn::tensor::Device;

/// RoIAlign alone, forward + backward on flex: `ROI_BENCH="N:out"` RoIs (default 1000 at
/// 7×7 and 256 at 14×14) spread over all four pooled levels of a batch-2, 512 px, 128-wide
/// FPN, sampling ratio 2.
///
/// ```text
/// ROI_BENCH="1000:7,256:14" cargo test --release --test maskrcnn_bench bench_roi_align -- --ignored --nocapture
/// ```
#[test]
#[ignore = "benchmark: run with --ignored --nocapture"]
fn bench_roi_align() {
    use burn::tensor::{Distribution, Tensor};
    use chicktrain::model::maskrcnn::pooler::pool_levels;
    use rand::{Rng, SeedableRng};
    let spec = std::env::var("ROI_BENCH").unwrap_or_else(|_| "1000:7,256:14".into());
    let dev = Device::flex().autodiff();
    let feats: Vec<Tensor<4>> = (2..6)
        .map(|l| {
            let s = 512 >> l;
            Tensor::random([2, 128, s, s], Distribution::Normal(0.0, 1.0), &dev).require_grad()
        })
        .collect();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
    for item in spec.split(',') {
        let (n, out) = item.split_once(':').expect("ROI_BENCH items are N:out");
        let (n, out): (usize, usize) = (n.parse().unwrap(), out.parse().unwrap());
        let rois: Vec<(usize, [f32; 4])> = (0..n)
            .map(|i| {
                let w: f32 = rng.random_range(16.0..300.0);
                let h: f32 = rng.random_range(16.0..300.0);
                let x: f32 = rng.random_range(0.0..512.0 - w);
                let y: f32 = rng.random_range(0.0..512.0 - h);
                (i % 2, [x, y, x + w, y + h])
            })
            .collect();
        let mut fwd = Vec::new();
        let mut bwd = Vec::new();
        for _ in 0..3 {
            let t0 = std::time::Instant::now();
            let pooled = pool_levels(&feats, 2, &rois, out, 2);
            let loss = pooled.powi_scalar(2).sum();
            let _ = loss.clone().into_data();
            let t1 = std::time::Instant::now();
            let g = loss.backward();
            let _ = feats[0].grad(&g).unwrap().into_data();
            fwd.push(t1.duration_since(t0).as_secs_f64() * 1e3);
            bwd.push(t1.elapsed().as_secs_f64() * 1e3);
        }
        fwd.sort_by(f64::total_cmp);
        bwd.sort_by(f64::total_cmp);
        println!(
            "roi_align {n} RoIs → {out}×{out}: forward {:.0} ms, backward {:.0} ms (median of 3)",
            fwd[1], bwd[1]
        );
    }
}
