//! Scores a trained engine on its held-out seen set-ups and the unseen indenters with the
//! contact-node breakdown and the force read from the predicted displacement, as JSON:
//! `cargo run -p ocm-npe --example npe_scores -- MODEL DATASET [DEGREE]` (degree of the force
//! functional, 0 by default as in `ocm npe eval`); also the validation set-ups and the contact
//! accuracy at other thresholds on the predicted -u_z (18-42 um).

use ocm_npe::Npe;
use ocm_npe::data::{Prepared, SetupSplit};
use ocm_npe::eval::{Extra, evaluate_with, fit_stiffness};
use ocm_tactile::dataset::{Dataset, TopSurface};
use ocm_tactile::gel::{Gel, GelMaterial};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let (model, dataset) = (&args[1], std::path::Path::new(&args[2]));
    let degree: usize = args.get(3).map_or(Ok(0), |d| d.parse())?;
    let npe = Npe::load(model)?;
    let split: SetupSplit = serde_json::from_value(Npe::run_meta(model)?["split"].clone())?;
    let ds = Dataset::read(dataset)?;
    let p = Prepared::from_dataset(&ds, &npe.config.scales);
    let digit = ocm_datadir::data_file(None, "digit")?;
    let gel = Gel::digit(
        digit.join(&ds.manifest.mesh),
        GelMaterial::new(ds.manifest.material[0], ds.manifest.material[1]),
    )?;
    let top = TopSurface::from_gel(&gel);
    let k = fit_stiffness(
        &p,
        &p.samples_of(&split.train),
        degree,
        npe.config.scales.displacement_m,
    )?;
    let thresholds: Vec<f64> = (0..=24).map(|i| 18e-6 + 1e-6 * f64::from(i)).collect();
    let mut out = serde_json::Map::new();
    for (name, setups) in [
        ("validation", &split.val),
        ("held-out seen", &split.test),
        ("unseen", &split.unseen),
    ] {
        let (scores, per) = evaluate_with(
            &npe,
            &p,
            &p.samples_of(setups),
            &gel,
            &top,
            8,
            &Extra {
                stiffness: Some(&k),
                thresholds_m: &thresholds,
                symmetrise: &[],
                ensemble: &[],
            },
        )?;
        let at: Vec<f64> = (0..thresholds.len())
            .map(|t| {
                100.0 * per.iter().map(|s| s.contact_accuracy_at[t]).sum::<f64>()
                    / per.len().max(1) as f64
            })
            .collect();
        let mut v = serde_json::to_value(scores)?;
        v["contact_accuracy_pct_at_threshold_um"] = thresholds
            .iter()
            .zip(&at)
            .map(|(t, a)| serde_json::json!([t * 1e6, a]))
            .collect();
        out.insert(name.into(), v);
    }
    println!("{}", serde_json::to_string_pretty(&out)?);
    Ok(())
}
