//! `ocm lut`: build, check, plot and export LUT images.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use indicatif::{ProgressBar, ProgressStyle};
use ocm_lutgen::OcmModel;
use ocm_lutgen::config::Config;
use ocm_lutgen::tables::{build_tables, check_accuracy};
use ocm_shared::lut::{LengthM, LutError, LutImage};
use ocm_shared::params::ParamPreset;

use crate::plot::{Chart, Series};

/// LUT subcommands.
#[derive(clap::Subcommand, Debug)]
pub enum LutCommand {
    /// Sample the energy model and write a LUT image.
    Build {
        /// Output image file.
        #[arg(long)]
        out: PathBuf,
        /// TOML configuration (OCM parameters and grids); the calibrated
        /// parameters and the 0-30 kPa grids if absent.
        #[arg(long)]
        config: Option<PathBuf>,
        /// Named OCM parameter set, in place of the configuration's `[ocm]`.
        #[arg(long, value_enum, conflicts_with = "config")]
        params: Option<Params>,
    },
    /// Validate an image and measure its inverse-lookup error against the f64 model.
    Check {
        /// The image.
        file: PathBuf,
        /// Configuration the image was built with.
        #[arg(long)]
        config: Option<PathBuf>,
        /// Named OCM parameter set the image was built with.
        #[arg(long, value_enum, conflicts_with = "config")]
        params: Option<Params>,
        /// Off-grid points checked per table.
        #[arg(long, default_value_t = 4000)]
        points: usize,
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
    },
    /// Plot force-strain and moment-angle curves stored in an image (PNG and SVG).
    Plot {
        /// The image.
        file: PathBuf,
        /// Output directory.
        #[arg(long)]
        out: PathBuf,
    },
    /// Export an image's tables as CSV.
    Export {
        /// The image.
        file: PathBuf,
        /// Output directory for `axial.csv` and `bending.csv`.
        #[arg(long)]
        out: PathBuf,
    },
}

/// Named OCM parameter sets (`docs/model.md`, "Calibrated parameters").
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Params {
    /// Table 3.1 geometry, stiffness scaled so that 0-30 kPa spans strain 0-0.6 (the default).
    Calibrated,
    /// Table 3.1 as printed (k_b 1.3 N/m, k_h 0.1 N/m: strain 0.6 at 1.5 kPa).
    #[value(name = "table-3.1")]
    Table31,
}

impl From<Params> for ParamPreset {
    fn from(p: Params) -> Self {
        match p {
            Params::Calibrated => Self::Calibrated,
            Params::Table31 => Self::Table31,
        }
    }
}

/// Runs an `ocm lut` subcommand.
pub fn run(cmd: LutCommand) -> Result<()> {
    match cmd {
        LutCommand::Build {
            out,
            config,
            params,
        } => build(&out, config.as_deref(), params),
        LutCommand::Check {
            file,
            config,
            params,
            points,
            json,
        } => check(&file, config.as_deref(), params, points, json),
        LutCommand::Plot { file, out } => plot(&file, &out),
        LutCommand::Export { file, out } => export(&file, &out),
    }
}

fn model_from(config: Option<&Path>, params: Option<Params>) -> Result<(Config, OcmModel)> {
    let mut cfg = Config::load(config)?;
    if let Some(p) = params {
        cfg.ocm = ParamPreset::from(p).ocm();
    }
    let model = OcmModel::new(cfg.ocm)?;
    Ok((cfg, model))
}

fn build(out: &Path, config: Option<&Path>, params: Option<Params>) -> Result<()> {
    let (cfg, model) = model_from(config, params)?;
    let bar = ProgressBar::new(0).with_style(
        ProgressStyle::with_template("{spinner} sampling tables [{bar:30}] {pos}/{len} rows")
            .expect("static template is valid"),
    );
    let tables = build_tables(&model, &cfg.table, &|done, total| {
        bar.set_length(total as u64);
        bar.set_position(done as u64);
    })?;
    bar.finish_and_clear();
    let bytes = tables.encode(&model)?;
    if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    std::fs::write(out, &bytes).with_context(|| format!("writing {}", out.display()))?;
    println!(
        "wrote {} ({} bytes, param hash {:#018x}); {} samples raised to keep rows monotone",
        out.display(),
        bytes.len(),
        model.params().hash(),
        tables.raised_samples
    );
    Ok(())
}

fn read_image(file: &Path) -> Result<Vec<u8>> {
    std::fs::read(file).with_context(|| format!("reading LUT image {}", file.display()))
}

fn check(
    file: &Path,
    config: Option<&Path>,
    params: Option<Params>,
    points: usize,
    json: bool,
) -> Result<()> {
    let (_, model) = model_from(config, params)?;
    let bytes = read_image(file)?;
    if let Err(LutError::CrcMismatch { stored, computed }) = LutImage::parse(&bytes) {
        if json {
            println!(
                "{}",
                serde_json::json!({"size_bytes": bytes.len(), "crc_ok": false,
                    "error": format!("CRC mismatch: stored {stored:#010x}, computed {computed:#010x}")})
            );
        }
        bail!(
            "{}: CRC mismatch (stored {stored:#010x}, computed {computed:#010x})",
            file.display()
        );
    }
    let acc = check_accuracy(&model, &bytes, points)
        .with_context(|| format!("checking {}", file.display()))?;
    if json {
        println!("{}", serde_json::to_string(&acc)?);
    } else {
        println!("{}: {} bytes, CRC ok", file.display(), acc.size_bytes);
        println!(
            "axial   F_A^-1: mean {:.5} %FS, max {:.5} %FS ({} off-grid points)",
            acc.axial_err_mean_pct_fs, acc.axial_err_max_pct_fs, acc.points
        );
        println!(
            "bending F_B^-1: mean {:.5} %FS, max {:.5} %FS",
            acc.bending_err_mean_pct_fs, acc.bending_err_max_pct_fs
        );
    }
    Ok(())
}

fn parse<'a>(bytes: &'a [u8], file: &Path) -> Result<LutImage<'a>> {
    LutImage::parse(bytes)
        .map_err(|e| anyhow::anyhow!("{}: invalid LUT image: {e:?}", file.display()))
}

fn plot(file: &Path, out: &Path) -> Result<()> {
    let bytes = read_image(file)?;
    let image = parse(&bytes, file)?;
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let ag = image.axial_grid();
    let (e0, e1): (f64, f64) = (ag.eps_min.to_num(), ag.eps_max.to_num());
    let samples = 241;
    let mut axial = Vec::new();
    for j in 0..ag.n_p {
        let p: f64 = ag.pressure_at(j).map_or(0.0, |p| p.to_num());
        let points = (0..samples)
            .map(|i| {
                let eps = e0 + (e1 - e0) * i as f64 / (samples - 1) as f64;
                Ok((
                    eps,
                    image
                        .axial_force_f64(eps, p)
                        .map_err(|e| anyhow::anyhow!("{e:?}"))?
                        .value,
                ))
            })
            .collect::<Result<Vec<_>>>()?;
        axial.push(Series {
            label: format!("{:.0} kPa", p / 1e3),
            points,
            dots: false,
        });
    }
    Chart {
        title: "Axial force F_A(eps, P) (LUT)",
        x_label: "strain eps [-]",
        y_label: "axial force F_z [N]",
        series: axial,
        equal_axes: false,
    }
    .write(out, "axial_force_strain")?;

    let bg = image.bending_grid();
    let (s0, s1): (f64, f64) = (bg.s_min.to_num(), bg.s_max.to_num());
    let mut bending = Vec::new();
    for k in 0..16 {
        let s = s0 + (s1 - s0) * f64::from(k) / 15.0;
        let phi_max: f64 = image
            .max_bend_angle(LengthM::from_num(s))
            .map_err(|e| anyhow::anyhow!("{e:?}"))?
            .to_num();
        let points = (0..samples)
            .map(|i| {
                let phi = phi_max * i as f64 / (samples - 1) as f64;
                Ok((
                    phi,
                    image
                        .bending_moment_f64(phi, s, 0.0)
                        .map_err(|e| anyhow::anyhow!("{e:?}"))?
                        .value,
                ))
            })
            .collect::<Result<Vec<_>>>()?;
        bending.push(Series {
            label: format!("s = {:.1} mm", s * 1e3),
            points,
            dots: false,
        });
    }
    Chart {
        title: "Bending moment M(phi, s) at P = 0 (LUT)",
        x_label: "bending angle phi [rad]",
        y_label: "moment M [N m]",
        series: bending,
        equal_axes: false,
    }
    .write(out, "moment_angle")?;
    println!(
        "wrote axial_force_strain.{{png,svg}} and moment_angle.{{png,svg}} to {}",
        out.display()
    );
    Ok(())
}

fn export(file: &Path, dir: &Path) -> Result<()> {
    let bytes = read_image(file)?;
    let image = parse(&bytes, file)?;
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let ag = image.axial_grid();
    let path = dir.join("axial.csv");
    let mut w =
        csv::Writer::from_path(&path).with_context(|| format!("writing {}", path.display()))?;
    w.write_record(["strain", "pressure_kpa", "force_n"])?;
    for j in 0..ag.n_p {
        for i in 0..ag.n_eps {
            let (Some(eps), Some(p), Some(f)) = (
                ag.strain_at(i),
                ag.pressure_at(j),
                image.axial_force_at(j, i),
            ) else {
                bail!("{}: axial table cell ({j}, {i}) missing", file.display());
            };
            w.write_record([
                eps.to_num::<f64>().to_string(),
                (p.to_num::<f64>() / 1e3).to_string(),
                f.to_num::<f64>().to_string(),
            ])?;
        }
    }
    w.flush()?;
    let bg = image.bending_grid();
    let path = dir.join("bending.csv");
    let mut w =
        csv::Writer::from_path(&path).with_context(|| format!("writing {}", path.display()))?;
    w.write_record([
        "arc_length_m",
        "bend_angle_rad",
        "max_bend_angle_rad",
        "moment_at_0kpa_nm",
        "moment_per_kpa_nm",
    ])?;
    for k in 0..bg.n_s {
        let (Some(s), Some(phi_max)) = (bg.length_at(k), image.phi_max_at(k)) else {
            bail!("{}: bending level {k} missing", file.display());
        };
        let phi_max = phi_max.to_num::<f64>();
        for i in 0..bg.n_u {
            let (Some(u), Some(m0), Some(m1)) = (
                bg.u_at(i),
                image.moment_at_zero_pressure_at(k, i),
                image.moment_per_pascal_f64_at(k, i),
            ) else {
                bail!("{}: bending cell ({k}, {i}) missing", file.display());
            };
            w.write_record([
                s.to_num::<f64>().to_string(),
                (u.to_num::<f64>() * phi_max).to_string(),
                phi_max.to_string(),
                m0.to_num::<f64>().to_string(),
                (m1 * 1e3).to_string(),
            ])?;
        }
    }
    w.flush()?;
    println!("wrote axial.csv and bending.csv to {}", dir.display());
    Ok(())
}
