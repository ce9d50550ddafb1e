//! Which loads on an indenter's footprint give per-placement modes that hold the held-out FEM
//! fields: the worst-frame projection limit of a saved reduced model's modes plus the rest
//! stiffness' responses to the chosen sets of footprint loads (`reduced::footprint_load_cases`),
//! with the error split into its normal (z) and in-plane parts. The sets `each_z` and
//! `each_xyz` stand for a unit force along z (or along x, y and z) on every footprint node
//! alone: the span of every linear response to a normal pressure (or any traction) on the
//! footprint, the best any such per-placement mode could do. `nl_<load>` stands for the
//! second-order field of a load's response: the response scaled to the deepest frame's depth
//! (largest |u_z|), then one modified-Newton correction with the rest tangent
//! (`RestStiffness::nonlinear_correction`), which holds the in-plane flow a linear response lacks.
//!
//! `cargo run -p ocm-tactile --example footprint_loads -- ROM RANKS SETUPS SETS [FEM_ROOTS]`
//! e.g. `-- out/tactile/rom 10,20 id3,r2-0021-texture1 foot+rim,foot+rim+out`.

use faer::Mat;
use ocm_tactile::gel::{Gel, GelMaterial};
use ocm_tactile::indent::Approach;
use ocm_tactile::indenter::{Indenter, Placed};
use ocm_tactile::reduced::{
    FOOTPRINT_RIM_M, FemSequence, ReducedModel, RestStiffness, footprint_load_cases,
};
use ocm_tactile::setup::{Setup, digit_setups};
use std::path::{Path, PathBuf};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 4 {
        return Err("usage: footprint_loads ROM RANKS SETUPS SETS [FEM_ROOTS]".into());
    }
    let rom = ReducedModel::load(Path::new(&args[0]))?;
    let ranks: Vec<usize> = args[1]
        .split(',')
        .map(|s| s.parse())
        .collect::<Result<_, _>>()?;
    let names: Vec<&str> = args[2].split(',').collect();
    let sets: Vec<Vec<&str>> = args[3].split(',').map(|s| s.split('+').collect()).collect();
    let roots: Vec<PathBuf> = args
        .get(4)
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
        let approach = Approach::new(name, &gel, &indenter, setup.placement)?;
        let placed = Placed {
            indenter: &indenter,
            pose: approach.pose_at(deepest),
        };
        let cases = footprint_load_cases(&gel, &placed, FOOTPRINT_RIM_M);
        let mut responses = Vec::new();
        for (label, loads) in &cases {
            let t = std::time::Instant::now();
            responses.push((*label, rest.respond(loads)?));
            eprintln!(
                "{name}: {label}: {} loaded nodes, back-solve {:.1} ms",
                loads.len(),
                t.elapsed().as_secs_f64() * 1e3
            );
        }
        let mut each: Vec<(&str, Vec<Vec<f64>>)> = Vec::new();
        // each_z / each_xyz: a unit force along z (or x, y and z) on every footprint node alone,
        // the span of every linear contact response (normal, or any traction) on that footprint.
        let foot: Vec<usize> = cases
            .iter()
            .find(|(k, _)| *k == "foot")
            .map(|(_, l)| l.iter().map(|(i, _)| *i).collect())
            .unwrap_or_default();
        let wants = |l: &str| sets.iter().any(|s| s.contains(&l));
        for (label, dirs) in [("each_z", 2..3), ("each_xyz", 0..3)] {
            if !wants(label) {
                continue;
            }
            let mut cols = Vec::new();
            for &i in &foot {
                for d in dirs.clone() {
                    let mut f = [0.0; 3];
                    f[d] = 1.0;
                    cols.push(rest.respond(&[(i, f)])?);
                }
            }
            each.push((label, cols));
        }
        let mut second = Vec::new();
        for (label, u) in &responses {
            let key = format!("nl_{label}");
            if !sets.iter().any(|s| s.contains(&key.as_str())) {
                continue;
            }
            let top = u.chunks(3).map(|c| c[2].abs()).fold(0.0, f64::max);
            let t = std::time::Instant::now();
            // A unit load's response concentrates under the loaded nodes: where it inverts an
            // element at the deepest depth the scale is halved (the correction's shape is
            // dominated by its second-order part at every admissible scale).
            let mut scale = deepest / top.max(1e-30);
            let du = loop {
                let scaled: Vec<f64> = u.iter().map(|v| v * scale).collect();
                match rest.nonlinear_correction(&gel, &scaled) {
                    Ok(du) => break du,
                    Err(_) if scale * top > 0.01 * deepest => scale *= 0.5,
                    Err(e) => return Err(e.into()),
                }
            };
            eprintln!(
                "{name}: {key}: correction {:.1} ms at max |u_z| {:.3} mm",
                t.elapsed().as_secs_f64() * 1e3,
                scale * top * 1e3
            );
            second.push((key, du));
        }
        for &r in &ranks {
            let m = rom.truncated(r)?;
            for set in std::iter::once(Vec::new()).chain(sets.iter().cloned()) {
                let mut extra: Vec<&Vec<f64>> = Vec::new();
                for l in &set {
                    if let Some((_, u)) = responses.iter().find(|(k, _)| k == l) {
                        extra.push(u);
                    }
                    if let Some((_, us)) = each.iter().find(|(k, _)| k == l) {
                        extra.extend(us.iter());
                    }
                    if let Some((_, u)) = second.iter().find(|(k, _)| k == l) {
                        extra.push(u);
                    }
                }
                let q = orthonormal(&m, &extra);
                let (mut worst, mut wz, mut wxy) = (0.0f64, 0.0, 0.0);
                for u in &fem.displacement {
                    let up = project(&q, u);
                    let e = ocm_tactile::metrics::nodal_rmse(&up, u)?;
                    if e > worst {
                        worst = e;
                        let (mut sz, mut sxy) = (0.0, 0.0);
                        for (a, b) in up.iter().zip(u) {
                            sz += (a[2] - b[2]).powi(2);
                            sxy += (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2);
                        }
                        wz = (sz / n as f64).sqrt();
                        wxy = (sxy / n as f64).sqrt();
                    }
                }
                println!(
                    "{name}: rank {r} + {} [{}]: worst-frame projection {:.4} mm (z {:.4}, in-plane {:.4})",
                    q.ncols() - r,
                    set.join("+"),
                    worst * 1e3,
                    wz * 1e3,
                    wxy * 1e3
                );
            }
        }
    }
    Ok(())
}

/// An orthonormal basis (3N x k) of the modes of `m` and the fields `extra`: the thin Q of a
/// Householder QR, without the columns whose R diagonal is below 1e-10 of the largest.
fn orthonormal(m: &ReducedModel, extra: &[&Vec<f64>]) -> Mat<f64> {
    let r = m.rank();
    let rows = m.modes.len() / r;
    let a = Mat::<f64>::from_fn(rows, r + extra.len(), |i, j| {
        if j < r {
            m.modes[i * r + j]
        } else {
            extra[j - r][i]
        }
    });
    let qr = a.qr();
    let q = qr.compute_thin_Q();
    let rd = qr.thin_R();
    let k = rd.nrows().min(rd.ncols());
    let big = (0..k).map(|i| rd[(i, i)].abs()).fold(0.0, f64::max);
    let keep: Vec<usize> = (0..k).filter(|&i| rd[(i, i)].abs() > 1e-10 * big).collect();
    Mat::from_fn(rows, keep.len(), |i, j| q[(i, keep[j])])
}

/// The projection Q Q^T u of a nodal field onto the columns of `q`.
fn project(q: &Mat<f64>, u: &[[f64; 3]]) -> Vec<[f64; 3]> {
    let x = Mat::<f64>::from_fn(3 * u.len(), 1, |i, _| u[i / 3][i % 3]);
    let c = q.transpose() * &x;
    let p = q * &c;
    (0..u.len())
        .map(|n| [p[(3 * n, 0)], p[(3 * n + 1, 0)], p[(3 * n + 2, 0)]])
        .collect()
}
