//! Symmetries of the top face, to augment the training set: an indentation turned half a
//! turn about the face's centre, or mirrored across one of its centre lines, is another
//! indentation of the same gel (an isotropic gel on a symmetric box with its base fixed), whose
//! field is the turned or mirrored field.
//!
//! The images are exact on the top face's nodes (the map must send every node onto a node)
//! and approximate inside the gel: a volume mesh that is not itself symmetric answers the
//! turned indenter with its own discretisation (the crate README measures that difference on
//! DIGIT_v8).

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

use crate::data::{NodeLocator, Prepared, Sample};
use crate::{NpeError, Result};

/// Largest x-y distance between a node's image and the node it lands on, m: far below the
/// node spacing (about 0.3 mm on DIGIT_v8) and above the mesh file's round-off.
pub const SYMMETRY_TOLERANCE_M: f64 = 5e-6;

/// An isometry of the top face about its centre (x-y), keeping z.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Symmetry {
    /// Half a turn about the vertical axis through the centre: (x, y) -> (-x, -y).
    Rot180,
    /// Mirror across the centre line x = c_x: x -> -x.
    MirrorX,
    /// Mirror across the centre line y = c_y: y -> -y.
    MirrorY,
}

impl Symmetry {
    /// Every symmetry, in the order of the CLI's names.
    pub const ALL: [Symmetry; 3] = [Symmetry::Rot180, Symmetry::MirrorX, Symmetry::MirrorY];

    /// The name of the CLI and of stored options.
    pub fn name(self) -> &'static str {
        match self {
            Symmetry::Rot180 => "rot180",
            Symmetry::MirrorX => "mirror-x",
            Symmetry::MirrorY => "mirror-y",
        }
    }

    /// Signs of the x and y components under the map.
    fn signs(self) -> [f64; 2] {
        match self {
            Symmetry::Rot180 => [-1.0, -1.0],
            Symmetry::MirrorX => [-1.0, 1.0],
            Symmetry::MirrorY => [1.0, -1.0],
        }
    }

    /// The image of the vector `v` (a displacement, a force).
    pub fn vector(self, v: [f64; 3]) -> [f64; 3] {
        let s = self.signs();
        [s[0] * v[0], s[1] * v[1], v[2]]
    }

    /// The image of the point `p` about the centre `c` (x, y).
    pub fn point(self, c: [f64; 2], p: [f64; 3]) -> [f64; 3] {
        let d = self.vector([p[0] - c[0], p[1] - c[1], p[2]]);
        [c[0] + d[0], c[1] + d[1], d[2]]
    }
}

impl fmt::Display for Symmetry {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Symmetry {
    type Err = String;

    fn from_str(s: &str) -> std::result::Result<Self, String> {
        Symmetry::ALL
            .into_iter()
            .find(|m| m.name() == s)
            .ok_or_else(|| {
                format!("unknown symmetry {s:?}: expected one of rot180, mirror-x, mirror-y")
            })
    }
}

/// The node permutation of `symmetry` on the top nodes `rest_m` about their bounding box's
/// centre: `perm[i]` is the node at node i's image. An error names the first node whose image
/// is not a node (within [`SYMMETRY_TOLERANCE_M`]) or that two nodes share.
pub fn permutation(rest_m: &[[f64; 3]], symmetry: Symmetry) -> Result<Vec<usize>> {
    let locator = NodeLocator::new(rest_m);
    let c = Prepared::top_center(rest_m);
    let mut perm = Vec::with_capacity(rest_m.len());
    let mut taken = vec![false; rest_m.len()];
    for (i, p) in rest_m.iter().enumerate() {
        let q = symmetry.point([c[0], c[1]], *p);
        let hit = locator.nearest(q[0], q[1]).filter(|&j| {
            let r = &rest_m[j];
            (r[0] - q[0]).hypot(r[1] - q[1]) <= SYMMETRY_TOLERANCE_M
                && (r[2] - q[2]).abs() <= SYMMETRY_TOLERANCE_M
        });
        let Some(j) = hit else {
            return Err(NpeError::Data(format!(
                "the top face is not symmetric under {symmetry}: node {i} at ({:.6}, {:.6}, \
                 {:.6}) m maps to ({:.6}, {:.6}) m, where no node lies within {} um",
                p[0],
                p[1],
                p[2],
                q[0],
                q[1],
                SYMMETRY_TOLERANCE_M * 1e6
            )));
        };
        if std::mem::replace(&mut taken[j], true) {
            return Err(NpeError::Data(format!(
                "the top face is not symmetric under {symmetry}: node {j} is the image of two nodes \
                 (the second is node {i})"
            )));
        }
        perm.push(j);
    }
    Ok(perm)
}

/// The image of `sample` under `symmetry` about the centre `c` (x, y), with `perm` from
/// [`permutation`]: points and forces mapped, and each node given its image node's (u, f)
/// mapped (u'(x) = S u(S x), as S is its own inverse).
pub fn map_sample(sample: &Sample, symmetry: Symmetry, c: [f64; 2], perm: &[usize]) -> Sample {
    let mut target = Vec::with_capacity(sample.target.len());
    for &j in perm {
        let r = &sample.target[6 * j..6 * j + 6];
        for part in [&r[..3], &r[3..]] {
            let v = symmetry.vector([0, 1, 2].map(|k| f64::from(part[k])));
            target.extend(v.map(|x| x as f32));
        }
    }
    Sample {
        setup: sample.setup,
        depth_m: sample.depth_m,
        force_n: symmetry.vector(sample.force_n),
        points_m: sample
            .points_m
            .iter()
            .map(|p| symmetry.point(c, *p))
            .collect(),
        target,
    }
}

/// A copy of `prepared` with the images of the samples `idx` under each of `symmetries`
/// appended (image samples keep their set-up), and the indices of the appended samples.
pub fn augmented(
    prepared: &Prepared,
    idx: &[usize],
    symmetries: &[Symmetry],
) -> Result<(Prepared, Vec<usize>)> {
    let c = Prepared::top_center(&prepared.rest_m);
    let mut out = prepared.clone();
    let mut added = Vec::with_capacity(idx.len() * symmetries.len());
    for (k, &s) in symmetries.iter().enumerate() {
        if symmetries[..k].contains(&s) {
            continue;
        }
        let perm = permutation(&prepared.rest_m, s)?;
        for &i in idx {
            let sample = prepared.samples.get(i).ok_or_else(|| {
                NpeError::Data(format!(
                    "sample {i} does not exist ({} samples)",
                    prepared.samples.len()
                ))
            })?;
            added.push(out.samples.len());
            out.samples.push(map_sample(sample, s, [c[0], c[1]], &perm));
        }
    }
    Ok((out, added))
}
