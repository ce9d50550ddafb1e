//! Trajectories from the reduced-FEM data sets written by `ocm mor` (NPY + JSON manifest).
//!
//! A data-set row holds the inputs of a step and the state *after* that step (its manifest says
//! so); a [`Trajectory`] step holds the state at `t` and the inputs applied from `t` to `t + 1`.
//! Trajectory step `i` is therefore the state of row `i` with the inputs of row `i + 1`, and a
//! sequence of `n` rows gives `n - 1` steps (the rest state before row 0 is not stored). Without
//! this shift the input that drives a transition would sit one step after the window that is
//! meant to predict it.

use std::path::Path;

use ocm_mor::dataset::{Dataset, Manifest, read};

use crate::error::{DynamicsError, Result};
use crate::trajectory::{FORCE_DIM, PRESSURE_DIM, Trajectory};

/// Reads the data set in `dir` and cuts it into its sequences.
pub fn read_trajectories(dir: &Path) -> Result<(Manifest, Vec<Trajectory>)> {
    let ds = read(dir, None)?;
    let trajs = split_sequences(&ds)?;
    Ok((ds.manifest, trajs))
}

/// Reads the data set in `dir` like [`read_trajectories`], but leaves out every sequence that
/// holds a non-finite value instead of failing; returns the indices of the sequences left out.
pub fn read_finite_trajectories(dir: &Path) -> Result<(Manifest, Vec<Trajectory>, Vec<usize>)> {
    let ds = read(dir, None)?;
    let mut kept = Vec::new();
    let mut dropped = Vec::new();
    for (i, t) in group_sequences(&ds)?.into_iter().enumerate() {
        let finite = [&t.pressure_kpa, &t.force_n, &t.state, &t.velocity]
            .iter()
            .all(|a| a.iter().all(|v| v.is_finite()));
        if finite {
            t.validate()
                .map_err(|e| DynamicsError::Data(format!("sequence {i}: {e}")))?;
            kept.push(t);
        } else {
            dropped.push(i);
        }
    }
    Ok((ds.manifest, kept, dropped))
}

/// The data set's rows grouped by sequence index, in order, each sequence validated.
pub fn split_sequences(ds: &Dataset) -> Result<Vec<Trajectory>> {
    let out = group_sequences(ds)?;
    for (i, t) in out.iter().enumerate() {
        t.validate()
            .map_err(|e| DynamicsError::Data(format!("sequence {i}: {e}")))?;
    }
    Ok(out)
}

fn group_sequences(ds: &Dataset) -> Result<Vec<Trajectory>> {
    let cols: Vec<usize> = ds.manifest.arrays.iter().map(|a| a.columns.len()).collect();
    let find = |file: &str| {
        ds.manifest
            .arrays
            .iter()
            .position(|a| a.file == file)
            .ok_or_else(|| DynamicsError::Data(format!("data set has no {file}")))
    };
    let (iseq, ip, iforce, ix, iv) = (
        find("sequence.npy")?,
        find("pressure_kpa.npy")?,
        find("tip_force_n.npy")?,
        find("xs.npy")?,
        find("xs_dot.npy")?,
    );
    if cols[ip] != PRESSURE_DIM || cols[iforce] != FORCE_DIM || cols[ix] != cols[iv] {
        return Err(DynamicsError::Data(format!(
            "unexpected column counts: pressure {}, force {}, X_S {}, dX_S/dt {}",
            cols[ip], cols[iforce], cols[ix], cols[iv]
        )));
    }
    let n = cols[ix];
    let rows = ds.manifest.samples;
    let seq = &ds.arrays[iseq];
    let mut out: Vec<Trajectory> = Vec::new();
    let mut current = f64::NAN;
    for r in 0..rows {
        let (s, step) = (seq[2 * r], seq[2 * r + 1]);
        if s != current {
            if step != 0.0 {
                return Err(DynamicsError::Data(format!(
                    "row {r}: sequence {s} starts at step {step}, not 0"
                )));
            }
            current = s;
            out.push(Trajectory {
                dt_s: ds.manifest.dt_s,
                state_dim: n,
                pressure_kpa: Vec::new(),
                force_n: Vec::new(),
                state: Vec::new(),
                velocity: Vec::new(),
            });
        }
        let t = out.last_mut().expect("a sequence was started");
        // Row r's inputs drive the step that ends at row r: they belong to the previous state.
        if step != 0.0 {
            t.pressure_kpa
                .extend_from_slice(&ds.arrays[ip][r * PRESSURE_DIM..(r + 1) * PRESSURE_DIM]);
            t.force_n
                .extend_from_slice(&ds.arrays[iforce][r * FORCE_DIM..(r + 1) * FORCE_DIM]);
        }
        let next_in_sequence = r + 1 < rows && seq[2 * (r + 1)] == s;
        if next_in_sequence {
            t.state
                .extend_from_slice(&ds.arrays[ix][r * n..(r + 1) * n]);
            t.velocity
                .extend_from_slice(&ds.arrays[iv][r * n..(r + 1) * n]);
        }
    }
    Ok(out)
}
