//! Latency of one engine call on the DIGIT_v8 top surface without a trained model or a data
//! set: an engine of the default architecture with seeded random weights (a call costs the
//! same whatever the weights) and the contact points of a sphere pressed into the face.
//! `cargo run -p ocm-npe --example npe_latency -- [--gap] [--head] [--prior] [--radius-mm R]
//! [--depth-mm D] [--calls N] [--threads T] [--json]`; the default sphere (16 mm radius, 1 mm
//! deep) gives about 1,600 contact points, as many as the held-out sample `ocm npe bench`
//! times. Also a fixed workload for `valgrind --tool=callgrind`, whose instruction counts do
//! not depend on the machine's load.

use ocm_learn::cpu;
use ocm_npe::data::Prepared;
use ocm_npe::model::NpeConfig;
use ocm_npe::{Npe, Surface};
use ocm_tactile::dataset::{ContactGrid, DatasetOptions, TopSurface};
use ocm_tactile::gel::{Gel, GelMaterial};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let flag = |name: &str| args.iter().any(|a| a == name);
    let value = |name: &str, default: f64| -> Result<f64, Box<dyn std::error::Error>> {
        match args.iter().position(|a| a == name) {
            Some(i) => Ok(args
                .get(i + 1)
                .ok_or_else(|| format!("{name} needs a value"))?
                .parse()?),
            None => Ok(default),
        }
    };
    let radius_m = value("--radius-mm", 16.0)? * 1e-3;
    let depth_m = value("--depth-mm", 1.0)? * 1e-3;
    let calls = value("--calls", 500.0)? as usize;
    let threads = value("--threads", 1.0)? as usize;

    let digit = ocm_datadir::data_file(None, "digit")?;
    let gel = Gel::digit(digit.join("DIGIT_v8.vtk"), GelMaterial::default())?;
    let top = TopSurface::from_gel(&gel);
    let spacing_m = DatasetOptions::default().grid_spacing_m;
    let grid = ContactGrid::for_gel(&gel, spacing_m)?;
    let center = Prepared::top_center(&top.rest_m);
    // The sphere's lowest point sits `depth_m` below the face's highest point, at its centre.
    let zc = center[2] - depth_m + radius_m;
    let points = grid.points_below(|x, y| {
        let r2 = (x - center[0]).powi(2) + (y - center[1]).powi(2);
        (r2 < radius_m * radius_m).then(|| zc - (radius_m * radius_m - r2).sqrt())
    });

    let mut cfg = NpeConfig::new(center, spacing_m);
    cfg.node_gap = flag("--gap");
    cfg.contact_prior = flag("--prior");
    cfg.contact_head = flag("--head");
    cfg.lambda_contact = if cfg.contact_head { 1.0 } else { 0.0 };
    let net = cfg.init(&cpu(), 0)?;
    let surface = Surface {
        rest_m: top.rest_m,
        edges: top.edges,
    };
    let npe = Npe::new(net, cfg, surface)?;
    let lat = ocm_npe::bench::latency(&npe, &points, 10.0, depth_m, 10, calls, threads)?;
    if flag("--json") {
        println!("{}", serde_json::to_string_pretty(&lat)?);
    } else {
        println!(
            "NPE call ({} nodes, {} points, gap {}, prior {}, head {}, {threads} thread(s)): \
             median {:.3} ms, p10 {:.3} ms, p90 {:.3} ms over {} calls",
            npe.surface.rest_m.len(),
            lat.points,
            npe.config.node_gap,
            npe.config.contact_prior,
            npe.config.contact_head,
            lat.median_ms,
            lat.p10_p90_ms[0],
            lat.p10_p90_ms[1],
            lat.calls
        );
    }
    Ok(())
}
