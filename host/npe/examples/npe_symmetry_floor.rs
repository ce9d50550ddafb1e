//! How far the FEM itself is from symmetric: the fields of set-ups and of their copies turned
//! half a turn about the top face's centre, compared node by node after the turn. The volume
//! mesh of DIGIT_v8 is not symmetric (its top face is), so the difference is the FEM's own
//! discretisation: the label noise that `ocm npe train --symmetries rot180` adds, and a floor
//! under the contact-node accuracy any engine can reach against this FEM. The mesh-converged
//! answers of a set-up and its copy are each other's images, so half the RMSE printed is a
//! lower bound on the FEM's own discretisation error in one of the two runs.
//!
//! Three steps (the FEM of the copies is the middle one):
//!
//! ```text
//! cargo run -p ocm-npe --example npe_symmetry_floor -- write /tmp/symdata sphere,edge
//! ocm tactile dataset --data /tmp/symdata --setups sphere,sphere_rot180,edge,edge_rot180 \
//!     --cache /tmp/symcache --out /tmp/symds
//! cargo run -p ocm-npe --example npe_symmetry_floor -- compare /tmp/symds sphere,edge [--json]
//! ```
//!
//! `write` makes a data folder beside the real one: links to every entry of its `digit/` but
//! the set-up files, which hold the named set-ups and their turned copies (`<name>_rot180`:
//! the origin turned about the centre, 180 degrees added to the z angle, exact for the set-up
//! files' R = Rz Ry Rx). `compare` prints, per pair and depth, the displacement RMSE between
//! the turned field and the copy's, the share of top nodes whose contact state (-u_z > 30 um)
//! agrees, and both forces.

use std::path::{Path, PathBuf};

use ocm_npe::data::Prepared;
use ocm_npe::symmetry::{self, Symmetry};
use ocm_tactile::dataset::{Dataset, TopSurface};
use ocm_tactile::gel::{Gel, GelMaterial};
use ocm_tactile::mask::CONTACT_THRESHOLD_M;
use ocm_tactile::metrics::nodal_rmse;

type Res<T> = Result<T, Box<dyn std::error::Error>>;

fn main() -> Res<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let names: Vec<String> = args
        .get(2)
        .ok_or("usage: npe_symmetry_floor write|compare <dir> <set-up,...> [--json]")?
        .split(',')
        .map(str::to_string)
        .collect();
    let dir = PathBuf::from(&args[1]);
    match args[0].as_str() {
        "write" => write(&dir, &names),
        "compare" => compare(&dir, &names, args.iter().any(|a| a == "--json")),
        other => Err(format!("unknown mode {other:?}: write or compare").into()),
    }
}

fn write(out: &Path, names: &[String]) -> Res<()> {
    let digit = ocm_datadir::data_file(None, "digit")?;
    let gel = Gel::digit(digit.join("DIGIT_v8.vtk"), GelMaterial::default())?;
    let c = Prepared::top_center(&TopSurface::from_gel(&gel).rest_m);
    let target = out.join("digit");
    std::fs::create_dir_all(&target)?;
    for entry in std::fs::read_dir(&digit)? {
        let entry = entry?;
        let link = target.join(entry.file_name());
        let settings = ["indenter_settings.json", "unseen_indenter_settings.json"];
        if settings.iter().any(|s| entry.file_name() == *s) || link.exists() {
            continue;
        }
        std::os::unix::fs::symlink(entry.path(), link)?;
    }
    // Each set-up file keeps its own named set-ups and their turned copies (an unseen
    // indenter's STL is looked up in the unseen folder).
    let mut found = vec![false; names.len()];
    for file in ["indenter_settings.json", "unseen_indenter_settings.json"] {
        let text = std::fs::read_to_string(digit.join(file))?;
        let all: Vec<serde_json::Value> = serde_json::from_str(&text)?;
        let mut kept = Vec::new();
        for (k, name) in names.iter().enumerate() {
            let Some(s) = all.iter().find(|s| s["name"] == name.as_str()) else {
                continue;
            };
            found[k] = true;
            let mut turned = s.clone();
            turned["name"] = format!("{name}_rot180").into();
            // The set-up files give the origin in mm; the centre is in m.
            let t: Vec<f64> = serde_json::from_value(s["translation"].clone())?;
            let p = Symmetry::Rot180.point([c[0] * 1e3, c[1] * 1e3], [t[0], t[1], t[2]]);
            turned["translation"] = serde_json::json!(p);
            let mut e: Vec<f64> = serde_json::from_value(s["orientation"].clone())?;
            e[2] += 180.0;
            turned["orientation"] = serde_json::json!(e);
            kept.push(s.clone());
            kept.push(turned);
        }
        let path = target.join(file);
        std::fs::write(&path, serde_json::to_string_pretty(&kept)?)?;
        println!("{} set-ups in {}", kept.len(), path.display());
    }
    if let Some(k) = found.iter().position(|f| !f) {
        return Err(format!("no set-up {} in the set-up files", names[k]).into());
    }
    Ok(())
}

fn compare(dir: &Path, names: &[String], json: bool) -> Res<()> {
    let ds = Dataset::read(dir)?;
    let perm = symmetry::permutation(&ds.top_rest_m, Symmetry::Rot180)?;
    let find = |n: &str| {
        ds.setups
            .iter()
            .find(|s| s.name == n)
            .ok_or_else(|| format!("no set-up {n} in {}", dir.display()))
    };
    let mut report = Vec::new();
    for name in names {
        let (a, b) = (find(name)?, find(&format!("{name}_rot180"))?);
        let steps = a.depth_m.len().min(b.depth_m.len());
        let mut rows = Vec::new();
        for k in 0..steps {
            let (ua, ub) = (&a.displacement_m[k], &b.displacement_m[k]);
            // a's field turned: node i takes its image node's displacement, turned
            let turned: Vec<[f64; 3]> = perm
                .iter()
                .map(|&j| Symmetry::Rot180.vector(ua[j]))
                .collect();
            let agree = turned
                .iter()
                .zip(ub)
                .filter(|(t, u)| (-t[2] > CONTACT_THRESHOLD_M) == (-u[2] > CONTACT_THRESHOLD_M))
                .count();
            let n = perm.len() as f64;
            rows.push(serde_json::json!({
                "depth_mm": a.depth_m[k] * 1e3,
                "rmse_mm": nodal_rmse(&turned, ub)? * 1e3,
                "contact_agreement_pct": 100.0 * agree as f64 / n,
                "force_z_n": [a.force_n[k][2], b.force_n[k][2]],
            }));
        }
        let mean = |key: &str| {
            rows.iter()
                .map(|r| r[key].as_f64().unwrap_or(f64::NAN))
                .sum::<f64>()
                / rows.len().max(1) as f64
        };
        let worst = rows
            .iter()
            .map(|r| r["contact_agreement_pct"].as_f64().unwrap_or(f64::NAN))
            .fold(f64::INFINITY, f64::min);
        if !json {
            println!(
                "{name}: {steps} depths | RMSE mean {:.4} mm | contact agreement mean {:.3} %, \
                 worst {worst:.3} %",
                mean("rmse_mm"),
                mean("contact_agreement_pct")
            );
            for r in &rows {
                println!(
                    "  {:.3} mm  RMSE {:.4} mm  agreement {:.3} %  F_z {:.3} / {:.3} N",
                    r["depth_mm"].as_f64().unwrap_or(f64::NAN),
                    r["rmse_mm"].as_f64().unwrap_or(f64::NAN),
                    r["contact_agreement_pct"].as_f64().unwrap_or(f64::NAN),
                    r["force_z_n"][0].as_f64().unwrap_or(f64::NAN),
                    r["force_z_n"][1].as_f64().unwrap_or(f64::NAN),
                );
            }
        }
        report.push(serde_json::json!({
            "setup": name,
            "rmse_mean_mm": mean("rmse_mm"),
            "contact_agreement_mean_pct": mean("contact_agreement_pct"),
            "contact_agreement_worst_pct": worst,
            "depths": rows,
        }));
    }
    if json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    }
    Ok(())
}
