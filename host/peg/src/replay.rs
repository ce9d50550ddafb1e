//! Trajectory replay (Ch.6.6.4): a recorded gripper path driven through the scene, with what
//! each sensor feels written per frame.

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::encoder::TactileEncoder;
use crate::error::{PegError, Result};
use crate::npe_encoder::NpeEncoder;
use crate::scene::{GripperPose, InHandError, PegScene, SceneConfig};
use ocm_npe::Fields;

/// Columns of a path CSV, in order (units in the names).
pub const PATH_COLUMNS: [&str; 5] = ["time_s", "x_m", "y_m", "z_m", "roll_rad"];

/// Writes a gripper path (rows `[time_s, x_m, y_m, z_m, roll_rad]`, hole frame) as CSV.
pub fn write_path(path: &Path, rows: &[[f64; 5]]) -> Result<()> {
    let mut w = csv::Writer::from_path(path).map_err(|e| PegError::file(path, e))?;
    w.write_record(PATH_COLUMNS)
        .map_err(|e| PegError::file(path, e))?;
    for r in rows {
        w.write_record(r.iter().map(|v| format!("{v:.9e}")))
            .map_err(|e| PegError::file(path, e))?;
    }
    w.flush().map_err(|e| PegError::file(path, e))
}

/// Reads a gripper path CSV: a header naming at least the [`PATH_COLUMNS`] (any order, other
/// columns ignored), at least two rows, finite values, strictly increasing time. Errors name the
/// file, the line and the column.
pub fn read_path(path: &Path) -> Result<Vec<[f64; 5]>> {
    let mut r = csv::ReaderBuilder::new()
        .trim(csv::Trim::All)
        .from_path(path)
        .map_err(|e| PegError::file(path, e))?;
    let header = r.headers().map_err(|e| PegError::file(path, e))?.clone();
    let mut idx = [0usize; 5];
    for (k, name) in PATH_COLUMNS.iter().enumerate() {
        idx[k] = header.iter().position(|h| h == *name).ok_or_else(|| {
            PegError::file(
                path,
                format!("no column `{name}` in the header (needs {PATH_COLUMNS:?})"),
            )
        })?;
    }
    let mut rows: Vec<[f64; 5]> = Vec::new();
    for (n, rec) in r.records().enumerate() {
        let line = n + 2;
        let rec = rec.map_err(|e| PegError::file(path, format!("line {line}: {e}")))?;
        let mut row = [0.0; 5];
        for k in 0..5 {
            let s = rec.get(idx[k]).unwrap_or("");
            let v: f64 = s.parse().map_err(|_| {
                PegError::file(
                    path,
                    format!(
                        "line {line}, column {}: `{s}` is not a number",
                        PATH_COLUMNS[k]
                    ),
                )
            })?;
            if !v.is_finite() {
                return Err(PegError::file(
                    path,
                    format!("line {line}, column {}: {v} is not finite", PATH_COLUMNS[k]),
                ));
            }
            row[k] = v;
        }
        if let Some(prev) = rows.last()
            && row[0] <= prev[0]
        {
            return Err(PegError::file(
                path,
                format!(
                    "line {line}: time {} s does not increase (previous {} s)",
                    row[0], prev[0]
                ),
            ));
        }
        rows.push(row);
    }
    if rows.len() < 2 {
        return Err(PegError::file(
            path,
            format!("{} rows; a path needs at least two", rows.len()),
        ));
    }
    Ok(rows)
}

fn interpolate(rows: &[[f64; 5]], t: f64) -> [f64; 5] {
    let k = rows.partition_point(|r| r[0] <= t);
    if k == 0 {
        return rows[0];
    }
    if k >= rows.len() {
        return rows[rows.len() - 1];
    }
    let (a, b) = (rows[k - 1], rows[k]);
    let w = (t - a[0]) / (b[0] - a[0]);
    std::array::from_fn(|i| a[i] + w * (b[i] - a[i]))
}

/// One replayed frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Frame {
    /// Time since the path's start, s.
    pub time_s: f64,
    /// Gripper pose reached.
    pub gripper: GripperPose,
    /// Peg tip (hole frame), m.
    pub tip_m: [f64; 3],
    /// Contact points per sensor (left, right), sensor frame, m.
    pub points_m: [Vec<[f64; 3]>; 2],
    /// Normal force per sensor, N.
    pub force_n: [f64; 2],
    /// Latent per sensor.
    pub latent: [Vec<f32>; 2],
}

/// Most frames one replay writes (an hour of control steps at 20 Hz is 72,000).
const MAX_FRAMES: usize = 200_000;

/// Drives the gripper along `rows` (the velocity that reaches the path's pose one control step
/// ahead, so tracking errors do not accumulate) holding the peg with `error`, one frame per
/// control step from the path's first to its last time, with the hole's axis at `hole_m` in
/// the path's frame (a demonstration's trial's hole; `[0, 0]` where the path's frame is the
/// hole's).
pub fn replay(
    config: &SceneConfig,
    rows: &[[f64; 5]],
    error: InHandError,
    hole_m: [f64; 2],
    encoder: &dyn TactileEncoder,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<Vec<Frame>> {
    if rows.len() < 2 {
        return Err(PegError::Invalid("a path needs at least two rows".into()));
    }
    let t0 = rows[0][0];
    let duration = rows[rows.len() - 1][0] - t0;
    let dt = config.control_dt_s();
    let frames_f = (duration / dt).floor();
    if frames_f.is_nan() || frames_f >= MAX_FRAMES as f64 {
        return Err(PegError::Invalid(format!(
            "the path lasts {duration} s: {frames_f} frames at the control step of {dt} s, more than {MAX_FRAMES}"
        )));
    }
    let n = frames_f as usize;
    let p0 = rows[0];
    let start = GripperPose {
        x_m: p0[1],
        y_m: p0[2],
        z_m: p0[3],
        roll_rad: p0[4],
    };
    let mut scene = PegScene::with_hole(config, start, error, hole_m)?;
    let mut frames = Vec::with_capacity(n + 1);
    for k in 0..=n {
        let contacts = scene.contacts()?;
        let latent = [
            encoder.latent(&contacts[0].points_m, contacts[0].force_n)?,
            encoder.latent(&contacts[1].points_m, contacts[1].force_n)?,
        ];
        let [left, right] = contacts;
        frames.push(Frame {
            time_s: scene.time_s(),
            gripper: scene.gripper(),
            tip_m: scene.peg_tip().0,
            force_n: [left.force_n, right.force_n],
            points_m: [left.points_m, right.points_m],
            latent,
        });
        progress(k, n);
        if k == n {
            break;
        }
        let target = interpolate(rows, t0 + (k + 1) as f64 * dt);
        let g = scene.gripper().to_array();
        let v = std::array::from_fn(|i| (target[i + 1] - g[i]) / dt);
        // The replay follows the record as closely as the scene allows: no speed limit.
        scene.step_unclamped(v)?;
    }
    Ok(frames)
}

/// Writes the frames into `dir`: `frames.csv` (time, pose, tip, forces, point counts),
/// `points.npy` (rows `[frame, sensor, x_m, y_m, z_m]`, sensor 0 left, 1 right), `latents.npy`
/// (frames x 2 latent_dim, left then right), `forces.npy` (frames x 2, N) and `replay.json`.
pub fn write_frames(dir: &Path, frames: &[Frame], error: InHandError, encoder: &str) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| PegError::file(dir, e))?;
    let p = dir.join("frames.csv");
    let mut w = csv::Writer::from_path(&p).map_err(|e| PegError::file(&p, e))?;
    w.write_record([
        "time_s",
        "x_m",
        "y_m",
        "z_m",
        "roll_rad",
        "tip_x_m",
        "tip_y_m",
        "tip_z_m",
        "force_left_n",
        "force_right_n",
        "points_left",
        "points_right",
    ])
    .map_err(|e| PegError::file(&p, e))?;
    let mut pts = Vec::new();
    let mut lat = Vec::new();
    let mut forces = Vec::new();
    let dim = frames.first().map_or(0, |f| f.latent[0].len());
    for (k, f) in frames.iter().enumerate() {
        let g = f.gripper;
        let rec = [
            f.time_s,
            g.x_m,
            g.y_m,
            g.z_m,
            g.roll_rad,
            f.tip_m[0],
            f.tip_m[1],
            f.tip_m[2],
            f.force_n[0],
            f.force_n[1],
        ];
        let mut rec: Vec<String> = rec.iter().map(|v| format!("{v:.9e}")).collect();
        rec.push(f.points_m[0].len().to_string());
        rec.push(f.points_m[1].len().to_string());
        w.write_record(rec).map_err(|e| PegError::file(&p, e))?;
        for (s, side) in f.points_m.iter().enumerate() {
            for q in side {
                pts.extend([k as f64, s as f64, q[0], q[1], q[2]]);
            }
        }
        for side in &f.latent {
            lat.extend(side.iter().map(|&v| f64::from(v)));
        }
        forces.extend(f.force_n);
    }
    w.flush().map_err(|e| PegError::file(&p, e))?;
    let npy = |name: &str, data: &[f64], cols: usize| -> Result<()> {
        let path = dir.join(name);
        ocm_fem::npy::write_f64_2d_path(&path, data, data.len() / cols.max(1), cols)
            .map_err(|e| PegError::file(&path, e))
    };
    npy("points.npy", &pts, 5)?;
    npy("latents.npy", &lat, 2 * dim)?;
    npy("forces.npy", &forces, 2)?;
    let manifest = serde_json::json!({
        "frames": frames.len(),
        "in_hand_error": error,
        "encoder": encoder,
        "latent_dim": dim,
        "files": {
            "frames.csv": "per frame: time (s), gripper pose (m, rad, hole frame), peg tip (m), normal force per sensor (N), contact points per sensor",
            "points.npy": "float64 (points, 5): frame, sensor (0 left, 1 right), x, y, z in the sensor frame (m; x, y on the gel surface, z into the gel)",
            "latents.npy": "float64 (frames, 2 latent_dim): left latent then right latent",
            "forces.npy": "float64 (frames, 2): normal force on the left and right gel (N)",
        },
    });
    let mp = dir.join("replay.json");
    let text = serde_json::to_string_pretty(&manifest).map_err(|e| PegError::file(&mp, e))?;
    std::fs::write(&mp, text).map_err(|e| PegError::file(&mp, e))
}

/// The engine's nodal fields of both pads (left, right) for every frame, from the frames'
/// contact points and forces; `progress(done, frames)` after each frame.
pub fn npe_fields(
    frames: &[Frame],
    npe: &NpeEncoder,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<Vec<[Fields; 2]>> {
    let mut out = Vec::with_capacity(frames.len());
    for (k, f) in frames.iter().enumerate() {
        out.push([
            npe.fields(&f.points_m[0], f.force_n[0])?,
            npe.fields(&f.points_m[1], f.force_n[1])?,
        ]);
        progress(k + 1, frames.len());
    }
    Ok(out)
}

/// Writes the engine's fields into `dir`: `npe_displacement.npy` and `npe_force.npy`
/// (float64, rows frame-major left then right, columns x, y, z of every top node: m and N in
/// the gel mesh's frame), `npe_nodes.npy` (the top nodes' rest positions, m) and
/// `npe_fields.csv` (per frame and sensor: largest displacement, and the force on the peg from
/// the summed nodal forces, mesh frame: z is the normal force).
pub fn write_npe_fields(dir: &Path, fields: &[[Fields; 2]], npe: &NpeEncoder) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| PegError::file(dir, e))?;
    let rest = &npe.npe().surface.rest_m;
    let cols = 3 * rest.len();
    let (mut u, mut f) = (Vec::new(), Vec::new());
    let p = dir.join("npe_fields.csv");
    let mut w = csv::Writer::from_path(&p).map_err(|e| PegError::file(&p, e))?;
    w.write_record([
        "frame",
        "sensor",
        "max_displacement_m",
        "force_on_peg_x_n",
        "force_on_peg_y_n",
        "force_on_peg_z_n",
    ])
    .map_err(|e| PegError::file(&p, e))?;
    for (k, pair) in fields.iter().enumerate() {
        for (s, fl) in pair.iter().enumerate() {
            u.extend(fl.displacement_m.iter().flatten());
            f.extend(fl.nodal_force_n.iter().flatten());
            let umax = fl
                .displacement_m
                .iter()
                .map(|d| (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt())
                .fold(0.0, f64::max);
            let t = fl.total_force_n();
            let rec = [umax, t[0], t[1], t[2]].map(|v| format!("{v:.6e}"));
            w.write_record([k.to_string(), s.to_string()].into_iter().chain(rec))
                .map_err(|e| PegError::file(&p, e))?;
        }
    }
    w.flush().map_err(|e| PegError::file(&p, e))?;
    let npy = |name: &str, data: &[f64], cols: usize| -> Result<()> {
        let path = dir.join(name);
        ocm_fem::npy::write_f64_2d_path(&path, data, data.len() / cols.max(1), cols)
            .map_err(|e| PegError::file(&path, e))
    };
    npy("npe_displacement.npy", &u, cols)?;
    npy("npe_force.npy", &f, cols)?;
    let nodes: Vec<f64> = rest.iter().flatten().copied().collect();
    npy("npe_nodes.npy", &nodes, 3)
}
