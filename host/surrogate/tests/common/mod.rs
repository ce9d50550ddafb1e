//! The chain the simulation and constraint tests share: dimensions of the fitted bellows
//! surrogate's order.

use ocm_surrogate::chain::ChainGeometry;

/// The test chain.
pub fn chain() -> ChainGeometry {
    ChainGeometry {
        base_height_m: 0.0216,
        segment_length_m: 0.0265,
        tcp_offset_m: 0.0395,
        link_radius_m: 0.074,
        base_radius_m: 0.067,
        top_radius_m: 0.083,
        top_thickness_m: 0.0195,
        link_mass_kg: 0.82 / 7.0,
        dummy_mass_kg: 1e-5,
    }
}
