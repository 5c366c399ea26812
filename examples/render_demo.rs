//! Temporary driver until the lead wires the CLI: renders a small dataset and benches.
//! `cargo run --release --example render_demo -- OUT_DIR COUNT SEED SIZE PRESET [bench N]`
fn main() -> anyhow::Result<()> {
    let a: Vec<String> = std::env::args().collect();
    let out = std::path::PathBuf::from(a.get(1).map(String::as_str).unwrap_or("/tmp/ct-render"));
    let count: u32 = a.get(2).map(|s| s.parse()).transpose()?.unwrap_or(16);
    let seed: u64 = a.get(3).map(|s| s.parse()).transpose()?.unwrap_or(0);
    let size: u32 = a.get(4).map(|s| s.parse()).transpose()?.unwrap_or(640);
    let preset = a.get(5).map(String::as_str).unwrap_or("synthetic");
    let mut opts = chicktrain::render::RenderOptions::preset(preset, size)?;
    opts.count = count;
    opts.seed = seed;
    // CT_OPTS='{"carcasses":[1,1]}' overrides option fields (JSON merged into the preset).
    if let Ok(extra) = std::env::var("CT_OPTS") {
        let mut v = serde_json::to_value(&opts)?;
        let e: serde_json::Value = serde_json::from_str(&extra)?;
        for (k, x) in e.as_object().into_iter().flatten() {
            v[k] = x.clone();
        }
        opts = serde_json::from_value(v)?;
    }
    if a.get(6).map(String::as_str) == Some("bench") {
        let n: usize = a.get(7).map(|s| s.parse()).transpose()?.unwrap_or(10);
        println!("{}", chicktrain::render::bench_render(&opts, n, seed)?);
        return Ok(());
    }
    let t = std::time::Instant::now();
    chicktrain::render::render_dataset(&opts, &out, true)?;
    println!(
        "{count} images in {:.2}s -> {}",
        t.elapsed().as_secs_f64(),
        out.display()
    );
    Ok(())
}
