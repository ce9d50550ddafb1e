//! Solves one bellows pressure state and prints the Fig 4.3 state.
//! `cargo run --release -p ocm-fem --example bellows_once [corotational|neo_hookean|neo_hookean_bulk] P1 P2 P3` (kPa).
use ocm_fem::bellows::{Bellows, BellowsConfig};
use ocm_fem::solve::statics::StaticSolver;
fn main() {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let mut cfg = BellowsConfig::default();
    if let Some(l) = args.first().cloned()
        && let Ok(law) = toml::from_str::<std::collections::BTreeMap<String, ocm_fem::bellows::Law>>(
            &format!("x = \"{l}\""),
        )
    {
        cfg.law = law["x"];
        args.remove(0);
    }
    let args: Vec<f64> = args
        .iter()
        .map(|a| a.parse().expect("pressure in kPa"))
        .collect();
    let t = std::time::Instant::now();
    let b = Bellows::load(
        "../shared/data/bellows-manipulator/ManipulatorWhole25.vtk",
        cfg,
    )
    .unwrap();
    println!(
        "load {:?}: nodes {} tets {} removed {} angles {:?} mass {:.4} kg",
        t.elapsed(),
        b.model.num_nodes(),
        b.model.elements.len(),
        b.removed_tets,
        b.chamber_angles_deg,
        b.model.total_mass()
    );
    let mut s = StaticSolver::new(&b.model).unwrap();
    println!("free dofs {} nnz {}", s.pattern.num_free(), s.pattern.nnz());
    let rest = b.state_of(&ocm_fem::model::State::at_rest(&b.model));
    println!("rest {rest:?}");
    let t = std::time::Instant::now();
    let p = if args.len() == 3 {
        args
    } else {
        vec![20.0, 0.0, 0.0]
    };
    let (st, rep) = b.solve_kpa(&mut s, &p).unwrap();
    println!("solve {:?} {rep:?} lu {}", t.elapsed(), s.lu_fallbacks());
    println!("{:?}", b.state_of(&st));
}
