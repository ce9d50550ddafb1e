//! Contact points of an object on a DIGIT pad, from rapier's contact manifolds, in the pad's
//! sensor frame, with the normal force of a linear gel foundation.

use rapier3d_f64::prelude::*;
use serde::{Deserialize, Serialize};

use crate::error::{PegError, Result};
use crate::patch::patch;

/// The sensor frame of a pad, in the pad collider's local frame: origin at the centre of the
/// gel's contact surface, x and y on that surface, z into the gel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensorFrame {
    /// Origin in the collider's local frame, m.
    pub origin_m: [f64; 3],
    /// The sensor's x, y and z axes in the collider's local frame (orthonormal, right-handed).
    pub axes: [[f64; 3]; 3],
}

impl SensorFrame {
    /// Maps a point of the collider's local frame into the sensor frame.
    pub fn to_sensor(&self, p: [f64; 3]) -> [f64; 3] {
        let d = [
            p[0] - self.origin_m[0],
            p[1] - self.origin_m[1],
            p[2] - self.origin_m[2],
        ];
        self.axes.map(|a| a[0] * d[0] + a[1] * d[1] + a[2] * d[2])
    }
}

/// The gel as a linear elastic foundation: pressure = modulus / thickness x local depth.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct GelFoundation {
    /// Young's modulus of the gel, Pa.
    pub modulus_pa: f64,
    /// Gel thickness, m.
    pub thickness_m: f64,
}

impl GelFoundation {
    /// Normal force of a patch of `area_m2` pressed `mean_depth_m` into the gel, N.
    pub fn force_n(&self, area_m2: f64, mean_depth_m: f64) -> f64 {
        self.modulus_pa / self.thickness_m * area_m2 * mean_depth_m.max(0.0)
    }
}

/// What one sensor feels: the contact points in its frame and the normal force.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct SensorContact {
    /// Points of the object inside the gel, sensor frame (x, y on the surface, z = depth into
    /// the gel), m.
    pub points_m: Vec<[f64; 3]>,
    /// Normal force on the gel, N.
    pub force_n: f64,
}

/// The contact of collider `object` on the pad collider `pad`: every manifold point with a
/// penetration (negative distance) becomes the object's point in the pad's sensor frame; the
/// force integrates the foundation over the convex patch of the points with their mean depth
/// (zero for point and edge contacts, which have no area on a rigid proxy).
pub fn pad_contact(
    world: &PhysicsWorld,
    pad: ColliderHandle,
    object: ColliderHandle,
    frame: &SensorFrame,
    gel: &GelFoundation,
) -> Result<SensorContact> {
    let (Some(pad_co), Some(obj_co)) = (world.colliders.get(pad), world.colliders.get(object))
    else {
        return Err(PegError::Scene(
            "contact query on a removed collider".into(),
        ));
    };
    let Some(pair) = world.contact_pair(pad, object) else {
        return Ok(SensorContact::default());
    };
    let object_is_first = pair.collider1 == object;
    let mut points = Vec::new();
    for m in pair.manifolds() {
        for c in &m.points {
            if c.dist >= 0.0 {
                continue;
            }
            let local = if object_is_first {
                c.local_p1
            } else {
                c.local_p2
            };
            let world_p = obj_co.position().transform_point(local);
            let q = pad_co.position().inverse_transform_point(world_p);
            let s = frame.to_sensor([q.x, q.y, q.z]);
            if s.iter().any(|v| !v.is_finite()) {
                return Err(PegError::Scene("a contact point is not finite".into()));
            }
            points.push(s);
        }
    }
    let force_n = match patch(&points) {
        Some(p) if p.area_m2 > 0.0 => {
            let depth = points.iter().map(|p| p[2]).sum::<f64>() / points.len() as f64;
            gel.force_n(p.area_m2, depth)
        }
        _ => 0.0,
    };
    Ok(SensorContact {
        points_m: points,
        force_n,
    })
}
