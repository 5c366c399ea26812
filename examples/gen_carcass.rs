//! Regenerates `assets/carcass.glb` from the procedural generator in `render::carcass`.
//! Run: `cargo run --release --example gen_carcass` (then commit the .glb).
fn main() -> anyhow::Result<()> {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/carcass.glb");
    chicktrain::render::glb::write_default_asset(&path)?;
    println!("wrote {}", path.display());
    Ok(())
}
