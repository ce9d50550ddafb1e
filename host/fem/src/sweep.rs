//! Pressure sweeps of the bellows manipulator and comparison with the original pipeline's table.

use crate::bellows::{Bellows, BellowsState, check_pressures};
use crate::model::State;
use crate::solve::statics::StaticSolver;
use crate::{FemError, Result};
use serde::Serialize;

/// One solved pressure state.
#[derive(Debug, Clone, Serialize)]
pub struct SweepPoint {
    /// Chamber pressures, kPa.
    pub pressures_kpa: [f64; 3],
    /// Fig 4.3 state.
    pub state: BellowsState,
    /// Newton iterations used.
    pub iterations: usize,
}

/// Solves the pressure states in order, each continued from the previous equilibrium.
/// `on_point` sees every result (progress bars, snapshots); the displacement field is passed too.
pub fn run(
    bellows: &Bellows,
    pressures_kpa: &[[f64; 3]],
    mut on_point: impl FnMut(usize, &SweepPoint, &State),
) -> Result<Vec<SweepPoint>> {
    let mut solver = StaticSolver::new(&bellows.model)?;
    let mut state = State::at_rest(&bellows.model);
    let mut prev = bellows.loads_kpa(&[0.0; 3]);
    let mut out = Vec::with_capacity(pressures_kpa.len());
    for (k, p) in pressures_kpa.iter().enumerate() {
        check_pressures(p)?;
        let to = bellows.loads_kpa(p);
        let rep = match solver.continue_to(&bellows.model, &mut state, &prev, &to) {
            Ok(r) => r,
            Err(_) => {
                // A hard jump between far-apart states: restart from rest with load stepping.
                state = State::at_rest(&bellows.model);
                solver.load_steps = 4;
                let r = solver.continue_to(
                    &bellows.model,
                    &mut state,
                    &bellows.loads_kpa(&[0.0; 3]),
                    &to,
                );
                solver.load_steps = 1;
                r.map_err(|e| FemError::Model(format!("pressure state {k} {p:?} kPa: {e}")))?
            }
        };
        prev = to;
        let pt = SweepPoint {
            pressures_kpa: *p,
            state: bellows.state_of(&state),
            iterations: rep.iterations,
        };
        on_point(k, &pt, &state);
        out.push(pt);
    }
    Ok(out)
}

/// A grid over each chamber's pressure, in serpentine order so that neighbours differ in one chamber.
pub fn grid(values_kpa: &[f64]) -> Vec<[f64; 3]> {
    let mut out = vec![];
    let n = values_kpa.len();
    for (i, &a) in values_kpa.iter().enumerate() {
        for jj in 0..n {
            let j = if i.is_multiple_of(2) { jj } else { n - 1 - jj };
            for kk in 0..n {
                let k = if (i * n + jj).is_multiple_of(2) {
                    kk
                } else {
                    n - 1 - kk
                };
                out.push([a, values_kpa[j], values_kpa[k]]);
            }
        }
    }
    out
}

/// CSV text of a sweep (header names units).
pub fn to_csv(points: &[SweepPoint]) -> String {
    let mut s = String::from(
        "p1_kpa,p2_kpa,p3_kpa,tcp_x_m,tcp_y_m,tcp_z_m,arc_length_m,curvature_per_m,bending_direction_deg,rot_x_rad,rot_y_rad,rot_z_rad,vol1_m3,vol2_m3,vol3_m3,iterations\n",
    );
    for p in points {
        let st = &p.state;
        let v = |k: usize| st.cavity_volumes_m3.get(k).copied().unwrap_or(f64::NAN);
        s.push_str(&format!(
            "{},{},{},{:.6e},{:.6e},{:.6e},{:.6e},{:.6e},{:.3},{:.6e},{:.6e},{:.6e},{:.6e},{:.6e},{:.6e},{}\n",
            p.pressures_kpa[0],
            p.pressures_kpa[1],
            p.pressures_kpa[2],
            st.tcp_m[0],
            st.tcp_m[1],
            st.tcp_m[2],
            st.arc_length_m,
            st.curvature_per_m,
            st.bending_direction_deg,
            st.plate_rotation_rad[0],
            st.plate_rotation_rad[1],
            st.plate_rotation_rad[2],
            v(0),
            v(1),
            v(2),
            p.iterations
        ));
    }
    s
}

/// Reads `Pressure_vs_Pos.csv` (pressures in kPa, positions in m): the first row per pressure triple.
pub fn read_reference(path: impl AsRef<std::path::Path>) -> Result<Vec<([f64; 3], [f64; 3])>> {
    let path = path.as_ref();
    let text = std::fs::read_to_string(path).map_err(|source| FemError::Io {
        path: path.display().to_string(),
        source,
    })?;
    let mut out: Vec<([f64; 3], [f64; 3])> = vec![];
    let mut seen = std::collections::HashSet::new();
    for (ln, line) in text
        .trim_start_matches('\u{feff}')
        .lines()
        .enumerate()
        .skip(1)
    {
        if line.trim().is_empty() {
            continue;
        }
        let v: Vec<f64> = line
            .split(',')
            .map(|t| t.trim().parse::<f64>())
            .collect::<std::result::Result<_, _>>()
            .map_err(|e| FemError::parse("CSV", format!("line {}", ln + 1), e.to_string()))?;
        if v.len() != 6 || v.iter().any(|x| !x.is_finite()) {
            return Err(FemError::parse(
                "CSV",
                format!("line {}", ln + 1),
                "expected 6 finite numbers",
            ));
        }
        let key = [v[0], v[1], v[2]].map(|x| (x * 1000.0).round() as i64);
        if seen.insert(key) {
            out.push(([v[0], v[1], v[2]], [v[3], v[4], v[5]]));
        }
    }
    Ok(out)
}

/// Comparison of a sweep with reference TCP positions at the same pressures.
#[derive(Debug, Clone, Serialize)]
pub struct Comparison {
    /// Matched states.
    pub matched: usize,
    /// RMSE of the TCP position in the mesh frame, m.
    pub rmse_m: f64,
    /// Rotation about z that best aligns the reference frame to the mesh frame, degrees.
    pub frame_rotation_deg: f64,
    /// RMSE after that rotation, m.
    pub rmse_aligned_m: f64,
    /// Ratio of mean lateral TCP excursion, FEM / reference.
    pub lateral_gain: f64,
}

/// Compares sweep TCPs with the reference rows of equal pressures.
pub fn compare(points: &[SweepPoint], reference: &[([f64; 3], [f64; 3])]) -> Result<Comparison> {
    let key = |p: &[f64; 3]| p.map(|x| (x * 1000.0).round() as i64);
    let map: std::collections::HashMap<[i64; 3], [f64; 3]> =
        reference.iter().map(|(p, x)| (key(p), *x)).collect();
    let pairs: Vec<([f64; 3], [f64; 3])> = points
        .iter()
        .filter_map(|p| map.get(&key(&p.pressures_kpa)).map(|r| (p.state.tcp_m, *r)))
        .collect();
    if pairs.is_empty() {
        return Err(FemError::Model(
            "no sweep state matches a reference pressure triple".into(),
        ));
    }
    let rmse = |rot: f64| {
        let (c, s) = (rot.cos(), rot.sin());
        (pairs
            .iter()
            .map(|(f, r)| {
                let (rx, ry) = (c * r[0] - s * r[1], s * r[0] + c * r[1]);
                (f[0] - rx).powi(2) + (f[1] - ry).powi(2) + (f[2] - r[2]).powi(2)
            })
            .sum::<f64>()
            / pairs.len() as f64)
            .sqrt()
    };
    // Best planar rotation by the 2-D Kabsch angle.
    let (mut sxy, mut sdot) = (0.0, 0.0);
    for (f, r) in &pairs {
        sdot += f[0] * r[0] + f[1] * r[1];
        sxy += r[0] * f[1] - r[1] * f[0];
    }
    let rot = sxy.atan2(sdot);
    let lat = |v: &[f64; 3]| (v[0] * v[0] + v[1] * v[1]).sqrt();
    let (lf, lr) = pairs
        .iter()
        .fold((0.0, 0.0), |a, (f, r)| (a.0 + lat(f), a.1 + lat(r)));
    Ok(Comparison {
        matched: pairs.len(),
        rmse_m: rmse(0.0),
        frame_rotation_deg: rot.to_degrees(),
        rmse_aligned_m: rmse(rot),
        lateral_gain: if lr > 0.0 { lf / lr } else { f64::NAN },
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn serpentine_grid_changes_one_chamber_at_a_time() {
        let g = grid(&[0.0, 10.0, 20.0]);
        assert_eq!(g.len(), 27);
        for w in g.windows(2) {
            let changed = (0..3).filter(|&k| w[0][k] != w[1][k]).count();
            assert_eq!(changed, 1, "{w:?}");
        }
    }
}
