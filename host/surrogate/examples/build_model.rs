//! Builds the surrogate from cached FEM samples (the same calls as `ocm surrogate urdf` and
//! `ocm surrogate map`) and prints the geometry and the mapping errors.
//! `cargo run -p ocm-surrogate --example build_model -- SAMPLES.json OUT_DIR [FORCE_SAMPLES [FORCE_HELD_OUT]]`
use ocm_surrogate::constraints::Limits;
use ocm_surrogate::fem_samples::FemSamples;
use ocm_surrogate::mapping::MatchConfig;
use ocm_surrogate::model::SurrogateModel;
fn main() {
    let a: Vec<String> = std::env::args().skip(1).collect();
    let samples = FemSamples::read(std::path::Path::new(&a[0])).expect("samples");
    let out = std::path::PathBuf::from(a.get(1).cloned().unwrap_or(".".into()));
    std::fs::create_dir_all(&out).expect("out dir");
    let t = std::time::Instant::now();
    let mut m = SurrogateModel::build(&samples, Limits::default(), MatchConfig::default(), |_| {})
        .expect("build");
    eprintln!("built in {:.2} s", t.elapsed().as_secs_f64());
    println!("{}", serde_json::to_string_pretty(&m.geometry).unwrap());
    println!("training {:?}", m.training);
    println!("held out {:?}", m.held_out);
    if let Some(n) = a.get(2).and_then(|x| x.parse::<usize>().ok()) {
        let mesh = ocm_datadir::data_file(None, "bellows-manipulator/ManipulatorWhole25.vtk")
            .expect("mesh");
        let b = ocm_fem::bellows::Bellows::load(mesh, ocm_fem::bellows::BellowsConfig::default())
            .expect("bellows");
        let t = std::time::Instant::now();
        let h = a.get(3).and_then(|x| x.parse::<usize>().ok()).unwrap_or(0);
        let p = SurrogateModel::calibration_pressures(n, 2);
        let held = ocm_surrogate::force::nested_random_pressures(h, 3);
        let fs = m
            .calibrate_force(
                &b,
                &p,
                &held,
                &ocm_surrogate::sim::SceneConfig::default(),
                ocm_surrogate::force::JigHold::TcpPinned,
                |k| eprintln!("jig {k}/{}", p.len() + h),
            )
            .expect("force calibration");
        eprintln!("force calibration in {:.1} s", t.elapsed().as_secs_f64());
        for (i, p) in fs.pressures_kpa.iter().enumerate() {
            let set = if i < fs.fit { "fit" } else { "held-out" };
            println!(
                "{set} P {p:?} kPa: surrogate {:?} N, FEM {:?} N",
                fs.surrogate_n[i], fs.fem_n[i]
            );
        }
        println!("{:?}", m.force_calibration);
    }
    m.write(&out.join("surrogate.json")).expect("write");
    std::fs::write(
        out.join("surrogate.urdf"),
        ocm_surrogate::urdf::to_urdf("ocm_bellows_surrogate", &m.geometry.chain, &m.limits),
    )
    .expect("urdf");
}
