//! The real pneumatic-cylinder friction records (`pneumatic-cylinder-friction/O-ring_<p>bar.csv`
//! in the data directory: a 3D-printed cylinder of 25 mm bore with an O-ring piston seal, moved
//! back and forth at constant supply pressure). The files are tab-separated without a header;
//! columns: time (ms), laser (V), pressure (V), force (V), piston displacement (mm), chamber
//! pressure (bar), force (N).
//!
//! They become simulator records: the ideal piston force `P A` (A = pi (12.5 mm)^2) is the
//! simulator's prediction of the measured force, the chamber pressure the input and the
//! displacement the simulator's state. The same record from the command line, with the one-line
//! conversion documented in the README:
//!
//! `awk -v OFS=, 'BEGIN{print "time_s,u_chamber_pressure_pa,x_displacement_mm,y_force_n,sim_force_n"} {print $1/1000,$6*1e5,$5,$7,$6*1e5*3.141592653589793*0.0125^2}' O-ring_1bar.csv > o1.csv`

use std::path::Path;

use crate::data::{Channel, Kind, Record};
use crate::error::IdentError;

/// Piston radius, metres (25 mm bore).
pub const PISTON_RADIUS_M: f64 = 0.0125;
/// The data set's folder inside the data directory.
pub const FOLDER: &str = "pneumatic-cylinder-friction";
/// The supply pressures recorded, bar (files `O-ring_<p>bar.csv`).
pub const PRESSURES_BAR: [u32; 4] = [1, 3, 5, 7];

/// Piston area, square metres.
pub fn piston_area_m2() -> f64 {
    std::f64::consts::PI * PISTON_RADIUS_M * PISTON_RADIUS_M
}

/// The file name of the record at `bar` supply pressure.
pub fn file_name(bar: u32) -> String {
    format!("O-ring_{bar}bar.csv")
}

/// Reads one record as a `series` record with the ideal force `P A` as simulated output.
pub fn load(path: &Path) -> Result<Record, IdentError> {
    let file = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|e| IdentError::Io {
        file: file.clone(),
        source: e,
    })?;
    parse(&text, &file)
}

/// Parses the tab-separated text; `file` names the source in errors.
pub fn parse(text: &str, file: &str) -> Result<Record, IdentError> {
    let area = piston_area_m2();
    let (mut t, mut p, mut x, mut f, mut sim) = (vec![], vec![], vec![], vec![], vec![]);
    for (k, line) in text.lines().enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        let v: Vec<&str> = line.split_whitespace().collect();
        if v.len() != 7 {
            return Err(IdentError::Parse {
                file: file.into(),
                line: k as u64 + 1,
                column: String::new(),
                message: format!("{} fields, expected 7 (tab-separated, no header)", v.len()),
            });
        }
        let num = |j: usize, name: &str| -> Result<f64, IdentError> {
            v[j].parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| IdentError::Parse {
                    file: file.into(),
                    line: k as u64 + 1,
                    column: name.into(),
                    message: format!("`{}` is not a finite number", v[j]),
                })
        };
        let bar = num(5, "chamber pressure (bar)")?;
        t.push(num(0, "time (ms)")? * 1e-3);
        p.push(bar * 1e5);
        x.push(num(4, "displacement (mm)")?);
        f.push(num(6, "force (N)")?);
        sim.push(bar * 1e5 * area);
    }
    let segment_starts = Record::starts_from_time(&t);
    let rec = Record {
        kind: Kind::Series,
        source: file.into(),
        time_s: t,
        segment_starts,
        inputs: vec![Channel::new("chamber_pressure_pa", "Pa", p)],
        outputs: vec![Channel::new("force_n", "N", f)],
        drives: vec![0],
        held_out: None,
        simulated: vec![Channel::new("force_n", "N", sim)],
        states: vec![Channel::new("displacement_mm", "mm", x)],
        sensitivities: Vec::new(),
    };
    rec.validate()?;
    Ok(rec)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_rows_and_computes_the_ideal_force() {
        let mut text = String::new();
        for i in 0..30 {
            text.push_str(&format!(
                "{}\t3.4\t0.5\t1.0\t{}\t2.000\t100.0\n",
                i * 10,
                i as f64 * 0.1
            ));
        }
        let r = parse(&text, "c.csv").unwrap();
        assert_eq!(r.len(), 30);
        assert!((r.time_s[3] - 0.03).abs() < 1e-12);
        // 2 bar on a 25 mm bore: 2e5 * pi * 0.0125^2 = 98.17 N
        assert!((r.simulated[0].values[0] - 98.174_770_424_681).abs() < 1e-9);
        let bad = parse("1\t2\t3\n", "d.csv").unwrap_err().to_string();
        assert!(bad.contains("d.csv") && bad.contains("line 1"), "{bad}");
    }
}
