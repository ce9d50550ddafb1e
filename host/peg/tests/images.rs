//! Rendered tactile images in replay: the engine's fields through the DIGIT renderer of
//! ocm-tactile (calibration and background from the data folder; the coarse DIGIT mesh).

use ocm_npe::{Fields, Surface};
use ocm_peg::images::{TactileImager, write_images};
use ocm_tactile::dataset::TopSurface;
use ocm_tactile::gel::{Gel, GelMaterial};
use ocm_tactile::optics::{PolyCalib, Renderer, RgbImage};
use ocm_tactile::real::{COLS, ROWS};

fn setup() -> Option<(Gel, Renderer, Surface)> {
    let digit = ocm_datadir::test_data("digit")?;
    let gel = Gel::digit(digit.join("DIGIT_remesh2.vtk"), GelMaterial::default()).unwrap();
    let calib = PolyCalib::from_npz(digit.join("optics/taxim_polycalib.npz")).unwrap();
    let bg =
        RgbImage::read_sized(digit.join("real-frames-edge6/edge6_00.jpg"), ROWS, COLS).unwrap();
    let renderer = Renderer::new(calib, &bg).unwrap();
    let top = TopSurface::from_gel(&gel);
    let surface = Surface {
        rest_m: top.rest_m,
        edges: top.edges,
    };
    Some((gel, renderer, surface))
}

/// A 0.4 mm deep Gaussian dent (sigma 1 mm) at the face's centre, or a flat face.
fn fields(surface: &Surface, depth_m: f64) -> Fields {
    let n = surface.rest_m.len();
    let c = ocm_npe::data::Prepared::top_center(&surface.rest_m);
    let displacement_m = surface
        .rest_m
        .iter()
        .map(|p| {
            let r2 = (p[0] - c[0]).powi(2) + (p[1] - c[1]).powi(2);
            [0.0, 0.0, -depth_m * (-r2 / (2.0 * 1e-6)).exp()]
        })
        .collect();
    Fields {
        displacement_m,
        nodal_force_n: vec![[0.0; 3]; n],
        ignored_points: 0,
    }
}

/// The left image's pixels of a side-by-side pair.
fn left(pair: &RgbImage, cols: usize) -> Vec<u8> {
    (0..pair.rows)
        .flat_map(|r| pair.data[r * pair.cols * 3..(r * pair.cols + cols) * 3].to_vec())
        .collect()
}

fn right(pair: &RgbImage, cols: usize) -> Vec<u8> {
    (0..pair.rows)
        .flat_map(|r| pair.data[((r + 1) * pair.cols - cols) * 3..(r + 1) * pair.cols * 3].to_vec())
        .collect()
}

#[test]
fn a_flat_pad_is_the_background_and_a_dent_changes_only_its_own_image() {
    let Some((gel, renderer, surface)) = setup() else {
        return;
    };
    let bg = renderer.background().data;
    let imager = TactileImager::new(&gel, renderer, &surface).unwrap();
    let flat = fields(&surface, 0.0);
    let dent = fields(&surface, 0.4e-3);
    let pair = imager.pair(&[flat.clone(), flat.clone()]).unwrap();
    assert_eq!(pair.rows, ROWS);
    assert_eq!(pair.cols, 2 * COLS + 4);
    assert_eq!(left(&pair, COLS), bg);
    assert_eq!(right(&pair, COLS), bg);
    let pair = imager.pair(&[dent, flat]).unwrap();
    assert_eq!(
        right(&pair, COLS),
        bg,
        "the untouched right pad stays the background"
    );
    let changed = left(&pair, COLS)
        .iter()
        .zip(&bg)
        .filter(|(a, b)| a.abs_diff(**b) > 3)
        .count();
    // The dent's slopes reach about 2.5 mm around the centre: hundreds of pixels at 16 px/mm.
    assert!(changed > 300, "only {changed} channel values changed");

    let dir = std::env::temp_dir().join(format!("ocm-peg-images-{}", std::process::id()));
    let frames = vec![[fields(&surface, 0.0), fields(&surface, 0.2e-3)]; 5];
    let written = write_images(&dir, &frames, &imager, 2, &mut |_, _| {}).unwrap();
    let names: Vec<String> = written
        .iter()
        .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
        .collect();
    assert_eq!(
        names,
        ["tactile_0000.png", "tactile_0002.png", "tactile_0004.png"]
    );
    let back = RgbImage::read(&written[1]).unwrap();
    assert_eq!((back.rows, back.cols), (ROWS, 2 * COLS + 4));
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn another_mesh_or_a_wrong_field_is_an_error() {
    let Some((gel, renderer, surface)) = setup() else {
        return;
    };
    let mut moved = surface.clone();
    moved.rest_m[7][0] += 1e-3;
    let e = TactileImager::new(&gel, renderer.clone(), &moved).unwrap_err();
    assert!(e.to_string().contains("top node 7"), "{e}");
    let mut fewer = surface.clone();
    fewer.rest_m.pop();
    assert!(TactileImager::new(&gel, renderer.clone(), &fewer).is_err());
    let imager = TactileImager::new(&gel, renderer, &surface).unwrap();
    let mut f = fields(&surface, 0.1e-3);
    f.displacement_m.pop();
    assert!(imager.image(&f.displacement_m).is_err());
    f.displacement_m.push([0.0, 0.0, f64::NAN]);
    assert!(imager.image(&f.displacement_m).is_err());
}
