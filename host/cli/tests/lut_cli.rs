//! The `ocm lut` and `ocm model` commands end to end, through the binary.

use std::path::{Path, PathBuf};
use std::process::Command;

use ocm_lutgen::{OcmModel, OcmParams};

fn ocm(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_ocm"))
        .args(args)
        .output()
        .expect("the ocm binary runs")
}

fn scratch(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn text(out: &std::process::Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    )
}

#[test]
fn build_check_plot_export() {
    let dir = scratch("lut_cli");
    let lut = dir.join("ocm.lut");
    let out = ocm(&["lut", "build", "--out", lut.to_str().unwrap()]);
    assert!(out.status.success(), "{}", text(&out));

    let out = ocm(&[
        "lut",
        "check",
        lut.to_str().unwrap(),
        "--json",
        "--points",
        "500",
    ]);
    assert!(out.status.success(), "{}", text(&out));
    let v: serde_json::Value =
        serde_json::from_slice(&out.stdout).expect("check --json prints JSON");
    assert_eq!(
        v["size_bytes"].as_u64().unwrap(),
        std::fs::metadata(&lut).unwrap().len()
    );
    assert!(v["size_bytes"].as_u64().unwrap() <= 32 * 1024);
    assert_eq!(v["crc_ok"], serde_json::Value::Bool(true));
    for key in ["axial_err_mean_pct_fs", "bending_err_mean_pct_fs"] {
        assert!(v[key].as_f64().unwrap() <= 0.1, "{key}: {v}");
    }
    for key in ["axial_err_max_pct_fs", "bending_err_max_pct_fs"] {
        assert!(v[key].as_f64().unwrap() <= 0.5, "{key}: {v}");
    }

    let plots = dir.join("plots");
    let out = ocm(&[
        "lut",
        "plot",
        lut.to_str().unwrap(),
        "--out",
        plots.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", text(&out));
    for f in [
        "axial_force_strain.png",
        "axial_force_strain.svg",
        "moment_angle.png",
        "moment_angle.svg",
    ] {
        let len = std::fs::metadata(plots.join(f)).unwrap().len();
        assert!(len > 10_000, "{f} is only {len} bytes");
    }
    let svg = std::fs::read_to_string(plots.join("axial_force_strain.svg")).unwrap();
    assert!(
        svg.contains("30 kPa") && svg.contains("0 kPa"),
        "legend lists the pressures"
    );

    let csv_dir = dir.join("csv");
    let out = ocm(&[
        "lut",
        "export",
        lut.to_str().unwrap(),
        "--out",
        csv_dir.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", text(&out));
    let axial = std::fs::read_to_string(csv_dir.join("axial.csv")).unwrap();
    let mut lines = axial.lines();
    assert_eq!(lines.next(), Some("strain,pressure_kpa,force_n"));
    assert_eq!(lines.count(), 16 * 129);
    // Exported values are the model's.
    let model = OcmModel::new(OcmParams::CALIBRATED).unwrap();
    // Fixed-point tables: the error is a share of the tables' full scale (measured 3.4e-4 N
    // against about 40 N, under 1e-5 of it).
    let forces: Vec<f64> = axial
        .lines()
        .skip(1)
        .map(|l| l.rsplit(',').next().unwrap().parse::<f64>().unwrap())
        .collect();
    let full_scale = forces.iter().fold(0.0f64, |m, f| m.max(f.abs()));
    assert!(full_scale > 1.0);
    for line in axial.lines().skip(1).step_by(97) {
        let v: Vec<f64> = line.split(',').map(|x| x.parse().unwrap()).collect();
        let exact = model.axial_force_n(v[0], v[1] * 1e3);
        assert!(
            (v[2] - exact).abs() < 5e-5 * full_scale,
            "{line}: model says {exact}"
        );
    }
}

#[test]
fn check_rejects_a_corrupted_image() {
    let dir = scratch("lut_cli_corrupt");
    let lut = dir.join("ocm.lut");
    assert!(
        ocm(&["lut", "build", "--out", lut.to_str().unwrap()])
            .status
            .success()
    );
    let mut bytes = std::fs::read(&lut).unwrap();
    let mid = bytes.len() / 2;
    bytes[mid] ^= 1;
    std::fs::write(&lut, &bytes).unwrap();
    let out = ocm(&["lut", "check", lut.to_str().unwrap(), "--json"]);
    assert!(!out.status.success());
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["crc_ok"], serde_json::Value::Bool(false));
    assert!(text(&out).contains("CRC mismatch"));
    // A config for other parameters is refused by hash.
    let cfg = dir.join("other.toml");
    std::fs::write(&cfg, "[ocm]\nhinge_stiffness_n_per_m = 0.2\n").unwrap();
    assert!(
        ocm(&["lut", "build", "--out", lut.to_str().unwrap()])
            .status
            .success()
    );
    let out = ocm(&[
        "lut",
        "check",
        lut.to_str().unwrap(),
        "--config",
        cfg.to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    assert!(text(&out).contains("parameter hash"), "{}", text(&out));
}

/// Runs `ocm model axial INPUT --out OUTPUT`.
fn model_axial(input: &std::path::Path, output: &std::path::Path) -> std::process::Output {
    ocm(&[
        "model",
        "axial",
        input.to_str().unwrap(),
        "--out",
        output.to_str().unwrap(),
    ])
}

#[test]
fn model_axial_adds_the_force_column() {
    let dir = scratch("model_axial");
    let input = dir.join("in.csv");
    std::fs::write(
        &input,
        "time_s,pressure_kpa,strain,note\n0.0,0,0.0,a\n0.1,10,0.25,b\n0.2,30,-0.5,c\n",
    )
    .unwrap();
    let output = dir.join("out.csv");
    let out = model_axial(&input, &output);
    assert!(out.status.success(), "{}", text(&out));
    let model = OcmModel::new(OcmParams::CALIBRATED).unwrap();
    let written = std::fs::read_to_string(&output).unwrap();
    let mut lines = written.lines();
    assert_eq!(
        lines.next(),
        Some("time_s,pressure_kpa,strain,note,force_n")
    );
    for line in lines {
        let f: Vec<&str> = line.split(',').collect();
        let (p, e, force): (f64, f64, f64) = (
            f[1].parse().unwrap(),
            f[2].parse().unwrap(),
            f[4].parse().unwrap(),
        );
        assert!((force - model.axial_force_n(e, p * 1e3)).abs() < 1e-8);
    }
}

#[test]
fn model_axial_warns_of_pressures_outside_the_table_range() {
    let dir = scratch("model_axial_range");
    let input = dir.join("in.csv");
    std::fs::write(
        &input,
        "time_s,pressure_kpa,strain\n0,10,0.1\n0.1,1e9,0.1\n0.2,-50,0.1\n0.3,20,0.1\n",
    )
    .unwrap();
    let output = dir.join("out.csv");
    let out = model_axial(&input, &output);
    // the rows are still written (the model extrapolates linearly), with a warning that counts
    // them and names the first
    assert!(out.status.success(), "{}", text(&out));
    let msg = text(&out);
    assert!(
        msg.contains("2 of 4 rows (the first on line 3: 1000000000 kPa) lie outside the configured pressure range [0, 30] kPa"),
        "{msg}"
    );
    assert_eq!(std::fs::read_to_string(&output).unwrap().lines().count(), 5);
    // inside the range: no warning
    std::fs::write(&input, "time_s,pressure_kpa,strain\n0,10,0.1\n").unwrap();
    let out = model_axial(&input, &output);
    assert!(
        out.status.success() && !text(&out).contains("warning"),
        "{}",
        text(&out)
    );
}

#[test]
fn model_axial_names_file_line_and_column_of_bad_input() {
    let dir = scratch("model_axial_bad");
    let output = dir.join("out.csv");
    for (body, needle) in [
        (
            "time_s,pressure_kpa,strain\n0,1,0.1\n0.1,abc,0.2\n",
            "line 3, column `pressure_kpa`",
        ),
        (
            "time_s,pressure_kpa,strain\n0,1,NaN\n",
            "line 2, column `strain`",
        ),
        (
            "time_s,pressure_kpa,strain\n0,1,5.0\n",
            "outside the model's range",
        ),
        (
            "time_s,pressure_kpa,strain\n0,1,0.1\n0.1,-150,0.1\n",
            "line 3, column `pressure_kpa`: -150 kPa is below absolute vacuum",
        ),
        ("time_s,strain\n0,0.1\n", "missing column `pressure_kpa`"),
    ] {
        let input = dir.join("in.csv");
        std::fs::write(&input, body).unwrap();
        let out = model_axial(&input, &output);
        assert!(!out.status.success());
        let msg = text(&out);
        assert!(msg.contains(needle) && msg.contains("in.csv"), "{msg}");
    }
}
