//! `bench render` without Burn: the renderer's timing report for the synthetic preset
//! with the given randomisation groups on, so renderer speed can be measured from a
//! `--no-default-features` build (minutes) instead of the full binary (Burn, 20+ min).
//! Run: `cargo run --release --no-default-features --example bench_render_groups --
//! SIZE IMAGES GROUPS` (GROUPS: none, all, or a comma list such as `carcass`).
fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let size: u32 = args.first().map_or(Ok(640), |s| s.parse())?;
    let images: usize = args.get(1).map_or(Ok(12), |s| s.parse())?;
    let groups = args.get(2).map_or("none", String::as_str);
    let mut opts = chicktrain::render::RenderOptions::synthetic(size);
    for g in groups.split(',').filter(|g| !g.is_empty() && *g != "none") {
        opts.randomize = if g == "all" {
            chicktrain::config::Randomize::ALL
        } else {
            opts.randomize.with(g, true)?
        };
    }
    // Family meshes are built once per process; time that apart from the images.
    let t = std::time::Instant::now();
    if opts.randomize.carcass {
        chicktrain::render::family::Family::prepare_all();
    }
    let prep = t.elapsed();
    let report = chicktrain::render::bench::bench_render(&opts, images, 0)?;
    println!("groups {groups}: family meshes {prep:.2?}; {report}");
    Ok(())
}
