//! Builds the surrogate from cached FEM samples (the same calls as `ocm surrogate urdf` and
//! `ocm surrogate map`) and prints the geometry and the mapping errors.
//! `cargo run -p ocm-surrogate --example build_model -- SAMPLES.json OUT_DIR [FORCE_SAMPLES]`
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
        let p = SurrogateModel::calibration_pressures(n, 2);
        let (sur, fem) = m
            .calibrate_force(&b, &p, &ocm_surrogate::sim::SceneConfig::default(), |k| {
                eprintln!("jig {k}/{n}")
            })
            .expect("force calibration");
        eprintln!("force calibration in {:.1} s", t.elapsed().as_secs_f64());
        for ((p, s), f) in p.iter().zip(&sur).zip(&fem) {
            println!("P {p:?} kPa: surrogate {s:?} N, FEM {f:?} N");
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
