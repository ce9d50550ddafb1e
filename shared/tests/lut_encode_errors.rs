//! The writer refuses bad tables, each fault with its own error naming where.

mod common;

use common::{Grids, Tables};
use ocm_shared::lut::{EncodeError, Grid, TableId, encode, encoded_len};

fn try_encode(tables: &Tables) -> Result<usize, EncodeError> {
    let mut out = vec![0u8; 64 * 1024];
    encode(0, &tables.axial(), &tables.bending(), &mut out)
}

#[test]
fn the_writer_needs_a_buffer_large_enough() {
    let tables = Tables::sample(Grids::DEFAULT);
    let needed = encoded_len(&tables.axial(), &tables.bending());
    let mut short = vec![0u8; needed - 1];
    assert_eq!(
        encode(0, &tables.axial(), &tables.bending(), &mut short),
        Err(EncodeError::BufferTooSmall {
            needed,
            got: needed - 1
        })
    );
    let mut budget = vec![0u8; ocm_shared::lut::LUT_CAPACITY];
    assert_eq!(
        encode(0, &tables.axial(), &tables.bending(), &mut budget),
        Ok(needed)
    );
}

#[test]
fn non_finite_values_are_named_by_table_row_and_column() {
    let mut tables = Tables::sample(Grids::DEFAULT);
    tables.force_n[3 * 129 + 17] = f64::NAN;
    assert_eq!(
        try_encode(&tables),
        Err(EncodeError::NotFinite {
            table: TableId::AxialForce,
            row: 3,
            col: 17
        })
    );
    let mut tables = Tables::sample(Grids::DEFAULT);
    tables.m1_nm_per_pa[5 * 129 + 2] = f64::INFINITY;
    assert_eq!(
        try_encode(&tables),
        Err(EncodeError::NotFinite {
            table: TableId::MomentPerPascal,
            row: 5,
            col: 2
        })
    );
    let mut tables = Tables::sample(Grids::DEFAULT);
    tables.phi_max_rad[9] = f64::NAN;
    assert_eq!(
        try_encode(&tables),
        Err(EncodeError::NotFinite {
            table: TableId::PhiMax,
            row: 9,
            col: 0
        })
    );
}

#[test]
fn a_decreasing_row_is_rejected_where_it_decreases() {
    let mut tables = Tables::sample(Grids::DEFAULT);
    // Make F[7][40] exceed F[7][41].
    tables.force_n[7 * 129 + 40] = tables.force_n[7 * 129 + 41] + 0.01;
    assert_eq!(
        try_encode(&tables),
        Err(EncodeError::NonMonotone {
            table: TableId::AxialForce,
            row: 7,
            col: 40,
            pressure_pa: 14_000.0
        })
    );
    // A bending row fine at zero pressure that falls at the top pressure:
    // a large positive slope at one point makes the next point lower there.
    let mut tables = Tables::sample(Grids::DEFAULT);
    let at = 2 * 129 + 60;
    let gap = tables.m0_nm[at + 1] - tables.m0_nm[at];
    tables.m1_nm_per_pa[at] = tables.m1_nm_per_pa[at + 1] + 2.0 * gap / 30_000.0;
    assert_eq!(
        try_encode(&tables),
        Err(EncodeError::NonMonotone {
            table: TableId::MomentAtZeroPressure,
            row: 2,
            col: 60,
            pressure_pa: 30_000.0
        })
    );
    // A flat run is allowed.
    let mut tables = Tables::sample(Grids::DEFAULT);
    tables.force_n[129 + 10] = tables.force_n[129 + 11];
    assert!(try_encode(&tables).is_ok());
}

#[test]
fn values_outside_their_q_format_are_rejected() {
    let mut tables = Tables::sample(Grids::DEFAULT);
    // I16F16 ends at 32768 N; keep the row monotone so only the range trips.
    tables.force_n[15 * 129 + 128] = 40_000.0;
    assert_eq!(
        try_encode(&tables),
        Err(EncodeError::OutOfRange {
            table: TableId::AxialForce,
            row: 15,
            col: 128,
            value: 40_000.0
        })
    );
    let mut tables = Tables::sample(Grids::DEFAULT);
    // I8F24 ends at 128 N*m.
    for k in 0..17 {
        tables.m0_nm[k * 129 + 128] = 200.0;
    }
    assert_eq!(
        try_encode(&tables),
        Err(EncodeError::OutOfRange {
            table: TableId::MomentAtZeroPressure,
            row: 0,
            col: 128,
            value: 200.0
        })
    );
    let mut tables = Tables::sample(Grids::DEFAULT);
    // M1 at the coarsest binary point (16) ends at 32768 N*m/Pa.
    tables.m1_nm_per_pa[3 * 129 + 128] = 1.0e5;
    assert_eq!(
        try_encode(&tables),
        Err(EncodeError::OutOfRange {
            table: TableId::MomentPerPascal,
            row: 3,
            col: 128,
            value: 1.0e5
        })
    );
    let mut tables = Tables::sample(Grids::DEFAULT);
    tables.phi_max_rad[4] = 0.0;
    assert_eq!(
        try_encode(&tables),
        Err(EncodeError::PhiMaxNotPositive { level: 4 })
    );
    tables.phi_max_rad[4] = -0.2;
    assert_eq!(
        try_encode(&tables),
        Err(EncodeError::PhiMaxNotPositive { level: 4 })
    );
}

#[test]
fn the_m1_binary_point_is_the_finest_that_fits() {
    let tables = Tables::sample(Grids::DEFAULT);
    let bytes = tables.encode(0);
    let lut = ocm_shared::lut::LutImage::parse(&bytes).unwrap();
    let bits = lut.bending_grid().m1_frac_bits;
    let largest = tables
        .m1_nm_per_pa
        .iter()
        .fold(0.0f64, |a, b| a.max(b.abs()));
    // Fits at `bits`, would not at `bits + 1`.
    assert!(largest * f64::from(bits).exp2() < f64::from(i32::MAX));
    assert!(largest * f64::from(bits + 1).exp2() >= f64::from(i32::MAX) - 0.5);
}

#[test]
fn malformed_grids_and_sizes_are_rejected() {
    let base = Tables::sample(Grids::DEFAULT);
    let mut out = vec![0u8; 64 * 1024];
    let mut axial = base.axial();
    axial.n_eps = 0;
    assert_eq!(
        encode(0, &axial, &base.bending(), &mut out),
        Err(EncodeError::EmptyGrid {
            grid: Grid::Strain,
            points: 0
        })
    );
    let mut axial = base.axial();
    axial.n_p = 1;
    assert_eq!(
        encode(0, &axial, &base.bending(), &mut out),
        Err(EncodeError::EmptyGrid {
            grid: Grid::Pressure,
            points: 1
        })
    );
    let mut axial = base.axial();
    axial.n_eps = 5000;
    assert_eq!(
        encode(0, &axial, &base.bending(), &mut out),
        Err(EncodeError::GridTooLarge {
            grid: Grid::Strain,
            points: 5000
        })
    );
    let mut axial = base.axial();
    axial.eps_max = axial.eps_min;
    assert_eq!(
        encode(0, &axial, &base.bending(), &mut out),
        Err(EncodeError::InvertedGrid { grid: Grid::Strain })
    );
    let mut axial = base.axial();
    axial.p_min_pa = 40_000.0;
    assert_eq!(
        encode(0, &axial, &base.bending(), &mut out),
        Err(EncodeError::InvertedGrid {
            grid: Grid::Pressure
        })
    );
    let mut axial = base.axial();
    axial.p_max_pa = f64::NAN;
    assert!(matches!(
        encode(0, &axial, &base.bending(), &mut out),
        Err(EncodeError::GridBound {
            grid: Grid::Pressure,
            ..
        })
    ));
    let mut bending = base.bending();
    bending.s_max_m = 1000.0; // beyond I8F24
    assert!(matches!(
        encode(0, &base.axial(), &bending, &mut out),
        Err(EncodeError::GridBound { grid: Grid::Length, value }) if value == 1000.0
    ));
    let mut bending = base.bending();
    bending.n_u = 0;
    assert_eq!(
        encode(0, &base.axial(), &bending, &mut out),
        Err(EncodeError::EmptyGrid {
            grid: Grid::NormalizedAngle,
            points: 0
        })
    );
    let mut bending = base.bending();
    bending.m0_nm = &base.m0_nm[1..];
    assert_eq!(
        encode(0, &base.axial(), &bending, &mut out),
        Err(EncodeError::SizeMismatch {
            table: TableId::MomentAtZeroPressure,
            expected: 17 * 129,
            got: 17 * 129 - 1
        })
    );
    let mut axial = base.axial();
    axial.force_n = &base.force_n[..100];
    assert_eq!(
        encode(0, &axial, &base.bending(), &mut out),
        Err(EncodeError::SizeMismatch {
            table: TableId::AxialForce,
            expected: 16 * 129,
            got: 100
        })
    );
}
