//! Whether the reduced model's error on held-out set-ups is the gel's nonlinearity: the reduced
//! solve with the default footprint modes (linear, rest stiffness), then the same fields after
//! one modified-Newton correction with the rest tangent (`RestStiffness::nonlinear_correction`:
//! -K_0^{-1} (f_int(X + u) - K_0 u)), computed at every frame, or once per placement at the
//! deepest frame and scaled by (depth / deepest)^2, against the FEM. Beside them, how far
//! the FEM itself is from linear: its first frame scaled to each depth against the frame
//! (for a flat punch, whose contact patch does not change, a linear gel would match it).
//!
//! `cargo run -p ocm-tactile --example nonlinear_lift -- ROM RANK SETUPS [FEM_ROOTS]`
//! e.g. `-- out/tactile/rom 10 id3,r2-0021-texture1`.

use ocm_tactile::gel::{Gel, GelMaterial};
use ocm_tactile::indenter::Indenter;
use ocm_tactile::metrics::nodal_rmse;
use ocm_tactile::reduced::{
    DEFAULT_FOOTPRINT_LOADS, Enrichment, FemSequence, ReducedIndentation, ReducedModel,
    ReducedOptions, RestStiffness, placement_model,
};
use ocm_tactile::setup::{Setup, digit_setups};
use std::path::{Path, PathBuf};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 3 {
        return Err("usage: nonlinear_lift ROM RANK SETUPS [FEM_ROOTS]".into());
    }
    let rom = ReducedModel::load(Path::new(&args[0]))?;
    let rank: usize = args[1].parse()?;
    let names: Vec<&str> = args[2].split(',').collect();
    let roots: Vec<PathBuf> = args
        .get(3)
        .map(|s| s.as_str())
        .unwrap_or("out/npe/fem,out/tactile/fem-random")
        .split(',')
        .map(PathBuf::from)
        .collect();
    let digit = ocm_datadir::data_file(None, "digit")?;
    let gel = Gel::digit(digit.join(&rom.info.mesh), GelMaterial::default())?;
    rom.check_gel(&gel)?;
    let all = digit_setups(&digit)?;
    let n = gel.num_nodes();
    let rest = RestStiffness::new(&gel)?;
    let m = rom.truncated(rank)?;
    let opts = ReducedOptions::for_modulus(gel.material.young_pa);
    let flat = |u: &[[f64; 3]]| -> Vec<f64> { u.iter().flatten().copied().collect() };
    let add = |u: &[[f64; 3]], du: &[f64], s: f64| -> Vec<[f64; 3]> {
        u.iter()
            .enumerate()
            .map(|(i, a)| {
                [
                    a[0] + s * du[3 * i],
                    a[1] + s * du[3 * i + 1],
                    a[2] + s * du[3 * i + 2],
                ]
            })
            .collect()
    };
    for name in names {
        let dir = roots
            .iter()
            .map(|r| r.join(name))
            .find(|d| d.join("u_001.npy").is_file())
            .ok_or_else(|| format!("no FEM folder named {name}"))?;
        let setup = Setup::beside_fem(&dir, name, &digit, &all)?;
        let fem = FemSequence::read(&dir, n, Some(50e-6))?;
        let deepest = fem.depth_m.iter().copied().fold(0.0, f64::max);
        let indenter = Indenter::from_stl(&setup.stl)?;
        let approach = ocm_tactile::indent::Approach::new(name, &gel, &indenter, setup.placement)?;
        let enrich = Enrichment {
            rest: &rest,
            loads: &DEFAULT_FOOTPRINT_LOADS,
        };
        let em = placement_model(&m, enrich, &gel, &indenter, &approach, deepest)?;
        let mut run = ReducedIndentation::new(name, &em, &gel, &indenter, setup.placement, opts)?;
        let mut fields = Vec::new();
        for &d in &fem.depth_m {
            let f = run.advance_to(d)?;
            fields.push(em.displacement(&f.q));
        }
        let t = std::time::Instant::now();
        let deep_corr = rest.nonlinear_correction(&gel, &flat(&fields[fields.len() - 1]))?;
        let cost = t.elapsed().as_secs_f64();
        let mut worst = [0.0f64; 3];
        let (d1, u1) = (fem.depth_m[0], &fem.displacement[0]);
        let mut worst_linear = (0.0f64, 0.0f64);
        for ((d, u), ur) in fem.depth_m.iter().zip(&fem.displacement).zip(&fields) {
            let lin = nodal_rmse(ur, u)?;
            let per_frame = nodal_rmse(
                &add(ur, &rest.nonlinear_correction(&gel, &flat(ur))?, 1.0),
                u,
            )?;
            let s = (d / deepest).powi(2);
            let per_placement = nodal_rmse(&add(ur, &deep_corr, s), u)?;
            let scaled: Vec<[f64; 3]> = u1.iter().map(|a| a.map(|v| v * d / d1)).collect();
            let linear = nodal_rmse(&scaled, u)?;
            let inplane: f64 = scaled
                .iter()
                .zip(u)
                .map(|(a, b)| (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2))
                .sum::<f64>();
            if linear > worst_linear.0 {
                worst_linear = (linear, (inplane / n as f64).sqrt());
            }
            println!(
                "{name} at {:.3} mm: reduced {:.4} mm, corrected per frame {:.4}, per placement {:.4}; \
                 FEM's first frame scaled {:.4}",
                d * 1e3,
                lin * 1e3,
                per_frame * 1e3,
                per_placement * 1e3,
                linear * 1e3
            );
            for (w, e) in worst.iter_mut().zip([lin, per_frame, per_placement]) {
                *w = w.max(e);
            }
        }
        println!(
            "{name}: worst frame: reduced {:.4} mm, corrected per frame {:.4}, per placement {:.4} \
             (one correction {:.1} ms); FEM's first frame scaled {:.4} mm (in-plane {:.4})",
            worst[0] * 1e3,
            worst[1] * 1e3,
            worst[2] * 1e3,
            cost * 1e3,
            worst_linear.0 * 1e3,
            worst_linear.1 * 1e3
        );
    }
    Ok(())
}
