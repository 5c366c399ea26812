//! Throwaway A/B (issue 37): batch-1 YOLO-n forward called from the main thread vs run
//! inside rayon's pool (`rayon::scope`), interleaved in one process.
use burn::module::Module;
use burn::tensor::{Device, Tensor, TensorData};
use chicktrain::model::yolo::{Scale, YoloSegConfig};
use chicktrain::util::tensor::to_host;
use std::time::Instant;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let rounds: usize = args.first().map(|s| s.parse().unwrap()).unwrap_or(40);
    let sizes: Vec<usize> = args
        .get(1)
        .map(|s| s.split(',').map(|x| x.parse().unwrap()).collect())
        .unwrap_or(vec![256, 320, 640]);
    let dev = Device::flex();
    let model = YoloSegConfig::new(Scale::N, 1).init(&dev).valid().fuse();
    for size in sizes {
        let px: Vec<f32> = (0..3 * size * size).map(|i| ((i * 7919) % 255) as f32 / 255.0).collect();
        let x = Tensor::<4>::from_data(TensorData::new(px, [1, 3, size, size]), &dev);
        let run = || {
            let out = model.forward(x.clone());
            let _ = to_host(out.cls_logits);
            let _ = to_host(out.proto);
        };
        for _ in 0..3 {
            run();
            rayon::scope(|_| run());
        }
        let (mut a, mut b) = (vec![], vec![]);
        for r in 0..rounds {
            let mut t = |inpool: bool| {
                let s = Instant::now();
                if inpool { rayon::scope(|_| run()) } else { run() }
                s.elapsed().as_secs_f64() * 1e3
            };
            if r % 2 == 0 {
                a.push(t(false));
                b.push(t(true));
            } else {
                b.push(t(true));
                a.push(t(false));
            }
        }
        a.sort_by(f64::total_cmp);
        b.sort_by(f64::total_cmp);
        let (ma, mb) = (a[a.len() / 2], b[b.len() / 2]);
        println!("{size} px: main thread {ma:.2} ms, in pool {mb:.2} ms, main/pool {:.3}", ma / mb);
    }
}
