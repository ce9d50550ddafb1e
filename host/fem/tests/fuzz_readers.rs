//! The mesh readers never panic, whatever the bytes.

use ocm_fem::mesh::{stl, vtk};
use proptest::prelude::*;

const VTK_ASCII: &str = "# vtk DataFile Version 2.0\nt\nASCII\nDATASET UNSTRUCTURED_GRID\nPOINTS 4 float\n0 0 0 1 0 0 0 1 0 0 0 1\nCELLS 2 9\n4 0 1 2 3\n3 0 1 2\nCELL_TYPES 2\n10\n5\n";

fn binary_vtk() -> Vec<u8> {
    let m = vtk::read_bytes(VTK_ASCII.as_bytes()).unwrap();
    let mut b = Vec::new();
    vtk::write(&mut b, &m, "fuzz", &[], &[]).unwrap();
    b
}

fn binary_stl() -> Vec<u8> {
    let s = "solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\nendloop\nendfacet\nendsolid\n";
    let m = stl::read_bytes(s.as_bytes()).unwrap();
    let mut b = Vec::new();
    stl::write_binary(&mut b, &m).unwrap();
    b
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 400, ..ProptestConfig::default() })]

    #[test]
    fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..400)) {
        let _ = vtk::read_bytes(&bytes);
        let _ = stl::read_bytes(&bytes);
        let _ = vtk::read_fields(&bytes);
    }

    #[test]
    fn mutated_valid_files_never_panic(
        which in 0usize..3,
        edits in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..8),
        cut in any::<prop::sample::Index>(),
    ) {
        let mut b = match which {
            0 => VTK_ASCII.as_bytes().to_vec(),
            1 => binary_vtk(),
            _ => binary_stl(),
        };
        for (i, v) in edits {
            let k = i.index(b.len());
            b[k] = v;
        }
        let _ = vtk::read_bytes(&b);
        let _ = stl::read_bytes(&b);
        let n = cut.index(b.len() + 1);
        let _ = vtk::read_bytes(&b[..n]);
        let _ = stl::read_bytes(&b[..n]);
    }

    #[test]
    fn ascii_numbers_in_place_of_counts_are_rejected_cleanly(n in any::<u64>()) {
        let s = VTK_ASCII.replace("POINTS 4", &format!("POINTS {n}"));
        let r = vtk::read_bytes(s.as_bytes());
        if n != 4 { prop_assert!(r.is_err()); }
    }
}
