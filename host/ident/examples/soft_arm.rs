//! Identifies what a quasi-static model gets wrong on the real soft-arm measurements (train on
//! the 13 `train` trials, score on the 4 `val` trials) and writes the report:
//! `cargo run -p ocm-ident --release --example soft_arm -- [OUT_DIR]`.

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let path = match ocm_ident::softarm::default_path(None) {
        Ok(p) => p,
        Err(e) => {
            eprintln!("SKIP: {e}");
            return Ok(());
        }
    };
    let rec = ocm_ident::softarm::load(&path)?;
    let t0 = std::time::Instant::now();
    let id = ocm_ident::identify(&rec, &ocm_ident::Config::default())?;
    let secs = t0.elapsed().as_secs_f64();
    print!("{}", ocm_ident::report::text(&id.report));
    println!("identification took {secs:.2} s");
    if let Some(dir) = std::env::args().nth(1) {
        let files = ocm_ident::report::write_all(&id, std::path::Path::new(&dir))?;
        eprintln!("wrote {files:?}");
    }
    Ok(())
}
