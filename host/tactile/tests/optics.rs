//! The DIGIT renderer and the real-frame comparison: flat gel = background, a spherical dimple's
//! slopes and gradient bins against the analytic ones, bad images and calibration files, the
//! measured mask of a known blob, the map fit on a constructed case, the whole comparison on
//! frames rendered from known fields, and the real data.

use ocm_datadir::test_data;
use ocm_tactile::TactileError;
use ocm_tactile::gel::{Gel, GelMaterial};
use ocm_tactile::mask::{Grid, mask_from_fn};
use ocm_tactile::metrics;
use ocm_tactile::optics::render::slopes;
use ocm_tactile::optics::{
    CameraMap, GridToMesh, PolyCalib, Renderer, RgbImage, SurfaceSampler, camera,
};
use ocm_tactile::real::{self, MaskOptions};
use std::io::Write;

const BINS: usize = 125;

/// A table whose R change is the magnitude bin, G the direction bin minus the flat one and B
/// zero everywhere: a rendered image then shows the bins the renderer picked.
fn bin_table() -> PolyCalib {
    let mut r = vec![0.0; BINS * BINS * 6];
    let mut g = vec![0.0; BINS * BINS * 6];
    let b = vec![0.0; BINS * BINS * 6];
    for i in 0..BINS {
        for j in 0..BINS {
            r[(i * BINS + j) * 6 + 5] = i as f64;
            g[(i * BINS + j) * 6 + 5] = j as f64 - 62.0;
        }
    }
    PolyCalib::from_tables(BINS, [&r, &g, &b], "bins").unwrap()
}

fn uniform(rows: usize, cols: usize, v: [u8; 3]) -> RgbImage {
    RgbImage {
        rows,
        cols,
        data: (0..rows * cols).flat_map(|_| v).collect(),
    }
}

/// Spherical cap of radius `rad` pressed `depth` towards the camera at (r0, c0), heights in m on
/// a grid of `p` m per pixel, and its analytic slopes (dh/drow, dh/dcol).
fn dimple(
    rows: usize,
    cols: usize,
    p: f64,
    rad: f64,
    depth: f64,
) -> (Vec<f32>, Vec<Option<(f64, f64)>>) {
    let (r0, c0) = (rows as f64 / 2.0, cols as f64 / 2.0);
    let a2 = rad * rad - (rad - depth).powi(2);
    let mut h = vec![0.0f32; rows * cols];
    let mut g = vec![None; rows * cols];
    for r in 0..rows {
        for c in 0..cols {
            let (y, x) = ((r as f64 + 0.5 - r0) * p, (c as f64 + 0.5 - c0) * p);
            let d2 = x * x + y * y;
            if d2 < a2 {
                let z = (rad * rad - d2).sqrt();
                h[r * cols + c] = (z - (rad - depth)) as f32;
                g[r * cols + c] = Some((-y / z, -x / z));
            }
        }
    }
    (h, g)
}

/// Zero heights leave every pixel exactly at the background, with the synthetic table and with
/// the real calibration on the real background through the real gel's sampler.
#[test]
fn flat_gel_renders_the_background() {
    let bg = RgbImage {
        rows: 24,
        cols: 32,
        data: (0..24 * 32 * 3).map(|i| (i * 37 % 256) as u8).collect(),
    };
    let r = Renderer::new(bin_table(), &bg).unwrap();
    assert_eq!(r.render(&vec![0.0; 24 * 32], 6.25e-5).unwrap(), bg);
    let (Some(npz), Some(frame0), Some(mesh)) = (
        test_data("digit/optics/taxim_polycalib.npz"),
        test_data("digit/real-frames-edge6/edge6_00.jpg"),
        test_data("digit/DIGIT_remesh2.vtk"),
    ) else {
        return;
    };
    let bg = RgbImage::read_sized(&frame0, 240, 320).unwrap();
    let r = Renderer::new(PolyCalib::from_npz(&npz).unwrap(), &bg).unwrap();
    let gel = Gel::digit(&mesh, GelMaterial::default()).unwrap();
    let s = SurfaceSampler::new(&gel, 240, 320, &CameraMap::for_grid(&Grid::for_gel(&gel)));
    assert!(s.covered() > 240 * 320 * 9 / 10, "{}", s.covered());
    let u = vec![[0.0; 3]; gel.num_nodes()];
    let img = real::render_step(&r, &s, &u).unwrap();
    assert_eq!(img, bg);
}

/// Central-difference slopes of a spherical cap (R = 4 mm, 0.5 mm deep, 31.25 um pixels) match
/// the analytic slopes -x/z inside the cap away from its rim, and the bins the renderer picks
/// (read back from the rendered image) are those of the analytic slopes.
#[test]
fn sphere_gradients_match_the_analytic_ones() {
    let (rows, cols, p) = (120usize, 160usize, 31.25e-6);
    let (h, g) = dimple(rows, cols, p, 4e-3, 0.5e-3);
    let s = slopes(&h, rows, cols, p as f32).unwrap();
    let rim = (4e-3f64.powi(2) - 3.5e-3f64.powi(2)).sqrt();
    let mut worst = 0.0f64;
    let mut n = 0;
    for r in 1..rows - 1 {
        for c in 1..cols - 1 {
            let k = r * cols + c;
            let (y, x) = (
                (r as f64 + 0.5 - rows as f64 / 2.0) * p,
                (c as f64 + 0.5 - cols as f64 / 2.0) * p,
            );
            if let Some((gr, gc)) = g[k]
                && x.hypot(y) < rim - 3.0 * p
            {
                worst = worst
                    .max((f64::from(s[k].0) - gr).abs())
                    .max((f64::from(s[k].1) - gc).abs());
                n += 1;
            }
        }
    }
    assert!(n > 5000, "{n}");
    // Truncation error of central differences: h''' p^2 / 6 ~ 1e-4 here; f32 heights add ~1e-4.
    assert!(worst < 2e-3, "worst slope error {worst}");

    let bg = uniform(rows, cols, [100, 100, 100]);
    let calib = bin_table();
    let img = Renderer::new(calib.clone(), &bg)
        .unwrap()
        .render(&h, p as f32)
        .unwrap();
    let (mut same, mut total, mut far) = (0, 0, 0);
    for r in 1..rows - 1 {
        for c in 1..cols - 1 {
            let k = r * cols + c;
            let Some((gr, gc)) = g[k] else { continue };
            let (y, x) = (
                (r as f64 + 0.5 - rows as f64 / 2.0) * p,
                (c as f64 + 0.5 - cols as f64 / 2.0) * p,
            );
            if x.hypot(y) > rim - 3.0 * p {
                continue;
            }
            let want = calib.bin(gr as f32, gc as f32);
            let (wi, wj) = (want / BINS, want % BINS);
            let got_i = i64::from(img.data[k * 3]) - 100;
            let got_j = i64::from(img.data[k * 3 + 1]) - 100 + 62;
            total += 1;
            if (got_i, got_j) == (wi as i64, wj as i64) {
                same += 1;
            }
            // Direction bins wrap around at -pi/pi.
            let dj = (got_j - wj as i64).rem_euclid(BINS as i64 - 1);
            if (got_i - wi as i64).abs() > 1 || dj.min(BINS as i64 - 1 - dj) > 1 {
                far += 1;
            }
        }
    }
    // Pixels whose slope lies within a bin's rounding of an edge may land next door; none further.
    assert!(same as f64 > 0.9 * total as f64, "{same} of {total}");
    assert_eq!(far, 0, "{far} pixels more than one bin off");
    // Off the cap the surface is flat: exactly the background.
    assert_eq!(&img.data[..3], &[100, 100, 100]);
}

/// Images of the wrong size or channel count and height fields of the wrong length give errors
/// that say what is wrong.
#[test]
fn wrong_images_are_refused() {
    let dir = std::env::temp_dir().join(format!("ocm-optics-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let grey = dir.join("grey.png");
    image::GrayImage::new(320, 240).save(&grey).unwrap();
    let e = RgbImage::read(&grey).unwrap_err().to_string();
    assert!(e.contains("grey.png") && e.contains("1 channel"), "{e}");
    let rgba = dir.join("rgba.png");
    image::RgbaImage::new(320, 240).save(&rgba).unwrap();
    let e = RgbImage::read(&rgba).unwrap_err().to_string();
    assert!(e.contains("4 channel"), "{e}");
    let small = dir.join("small.png");
    image::RgbImage::new(100, 80).save(&small).unwrap();
    let e = RgbImage::read_sized(&small, 240, 320)
        .unwrap_err()
        .to_string();
    assert!(e.contains("100 x 80") && e.contains("320 x 240"), "{e}");
    let big = dir.join("big.png");
    image::RgbImage::from_pixel(640, 480, image::Rgb([10, 20, 30]))
        .save(&big)
        .unwrap();
    let half = RgbImage::read_sized(&big, 240, 320).unwrap();
    assert_eq!(
        (half.rows, half.cols, &half.data[..3]),
        (240, 320, &[10, 20, 30][..])
    );
    let r = Renderer::new(bin_table(), &uniform(24, 32, [1, 2, 3])).unwrap();
    let e = r.render(&[0.0; 10], 1e-4).unwrap_err().to_string();
    assert!(e.contains("10 values") && e.contains("24 x 32"), "{e}");
    let mut h = vec![0.0f32; 24 * 32];
    h[40] = f32::NAN;
    let e = r.render(&h, 1e-4).unwrap_err().to_string();
    assert!(e.contains("row 1, col 8"), "{e}");
    let other = uniform(20, 32, [0, 0, 0]);
    let e = real::measured_mask(&other, &uniform(24, 32, [0, 0, 0]), &MaskOptions::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains("32 x 20") && e.contains("32 x 24"), "{e}");
    std::fs::remove_dir_all(&dir).ok();
}

fn npz(entries: &[(&str, Vec<u8>)]) -> Vec<u8> {
    let mut buf = std::io::Cursor::new(Vec::new());
    {
        let mut z = zip::ZipWriter::new(&mut buf);
        let o =
            zip::write::FileOptions::default().compression_method(zip::CompressionMethod::Stored);
        for (name, bytes) in entries {
            z.start_file(*name, o).unwrap();
            z.write_all(bytes).unwrap();
        }
        z.finish().unwrap();
    }
    buf.into_inner()
}

fn npy(descr: &str, shape: &str, body: &[u8]) -> Vec<u8> {
    let h = format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': {shape}, }}\n");
    let mut b = b"\x93NUMPY\x01\x00".to_vec();
    b.extend_from_slice(&(h.len() as u16).to_le_bytes());
    b.extend_from_slice(h.as_bytes());
    b.extend_from_slice(body);
    b
}

/// A missing, non-zip, incomplete or mis-shaped calibration gives an error naming the file and
/// the array; a well-formed small one loads with its values.
#[test]
fn bad_calibration_files_are_named() {
    let e = PolyCalib::from_npz("/nonexistent/polycalib.npz")
        .unwrap_err()
        .to_string();
    assert!(e.contains("/nonexistent/polycalib.npz"), "{e}");
    let e = PolyCalib::from_npz_bytes(b"not a zip at all", "c.npz")
        .unwrap_err()
        .to_string();
    assert!(e.contains("c.npz") && e.contains("zip"), "{e}");
    let bins = npy("<i8", "()", &3i64.to_le_bytes());
    let table: Vec<u8> = (0..54).flat_map(|i| (i as f64).to_le_bytes()).collect();
    let t = npy("<f8", "(3, 3, 6)", &table);
    let e = PolyCalib::from_npz_bytes(
        &npz(&[
            ("bins.npy", bins.clone()),
            ("grad_r.npy", t.clone()),
            ("grad_g.npy", t.clone()),
        ]),
        "c.npz",
    )
    .unwrap_err();
    assert!(matches!(e, TactileError::Calibration { .. }));
    assert!(e.to_string().contains("grad_b"), "{e}");
    let wrong = npy("<f8", "(3, 6, 3)", &table);
    let e = PolyCalib::from_npz_bytes(
        &npz(&[
            ("bins.npy", bins.clone()),
            ("grad_r.npy", t.clone()),
            ("grad_g.npy", wrong),
            ("grad_b.npy", t.clone()),
        ]),
        "c.npz",
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("grad_g") && e.contains("[3, 6, 3]"), "{e}");
    let truncated = npy("<f8", "(3, 3, 6)", &table[..100]);
    let e = PolyCalib::from_npz_bytes(
        &npz(&[
            ("bins.npy", bins.clone()),
            ("grad_r.npy", truncated),
            ("grad_g.npy", t.clone()),
            ("grad_b.npy", t.clone()),
        ]),
        "c.npz",
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("grad_r") && e.contains("truncated"), "{e}");
    let c = PolyCalib::from_npz_bytes(
        &npz(&[
            ("bins.npy", bins),
            ("grad_r.npy", t.clone()),
            ("grad_g.npy", t.clone()),
            ("grad_b.npy", t),
        ]),
        "c.npz",
    )
    .unwrap();
    // Bin (1, 2), channel G, constant coefficient: element (1 * 3 + 2) * 6 + 5 = 35.
    assert_eq!(c.eval(5, 1, &[0.0, 0.0, 0.0, 0.0, 0.0, 1.0]), 35.0);
}

/// A disc brighter than a noisy background comes back as the measured mask: IoU with the disc
/// above 0.95 and its centroid within half a pixel.
#[test]
fn measured_mask_of_a_known_blob() {
    use rand::{Rng, SeedableRng};
    let (rows, cols) = (240, 320);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(17);
    let bg = RgbImage {
        rows,
        cols,
        data: (0..rows * cols * 3)
            .map(|_| rng.random_range(90..110))
            .collect(),
    };
    let (cr, cc, rad) = (100.0, 170.0, 30.0);
    let inside = |r: usize, c: usize| (r as f64 + 0.5 - cr).hypot(c as f64 + 0.5 - cc) < rad;
    let mut frame = bg.clone();
    for r in 0..rows {
        for c in 0..cols {
            for ch in 0..3 {
                let k = (r * cols + c) * 3 + ch;
                // Noise of +-3 everywhere, +40 in the disc.
                let n: i32 = rng.random_range(-3..=3);
                let v = i32::from(bg.data[k]) + n + if inside(r, c) { 40 } else { 0 };
                frame.data[k] = v.clamp(0, 255) as u8;
            }
        }
    }
    let m = real::measured_mask(&frame, &bg, &MaskOptions::default()).unwrap();
    // The 5 x 5 box blur turns the disc's step edge into a ramp 5 pixels wide; the threshold
    // (10 of the 40 levels, a quarter) cuts it 0.25 x 5 = 1.25 pixels outside the edge.
    let grown = |r: usize, c: usize| (r as f64 + 0.5 - cr).hypot(c as f64 + 0.5 - cc) < rad + 1.25;
    let truth = mask_from_fn(real::image_grid(rows, cols), grown);
    let iou = metrics::iou(&m, &truth).unwrap();
    assert!(iou > 0.95, "IoU {iou}");
    let (a, b) = (m.stats(), truth.stats());
    assert!(metrics::centroid_error(&a, &b) < 0.5);
    // Nothing but noise: an empty mask.
    let quiet = real::measured_mask(&bg, &bg, &MaskOptions::default()).unwrap();
    assert_eq!(quiet.count(), 0);
}

/// A gel grid of 240 x 320 pixels of 0.0625 mm (the whole DIGIT gel at the frames' size).
fn gel_grid_240x320() -> Grid {
    Grid {
        origin_m: [0.0, 0.0],
        pixel_m: 0.0625e-3,
        cols: 320,
        rows: 240,
    }
}

/// Masks made by warping gel-grid ellipses through a known map are fitted back: the map and
/// the step offset are recovered and the IoU is near 1.
#[test]
fn map_fit_recovers_a_known_map() {
    let gel_grid = gel_grid_240x320();
    let truth = CameraMap {
        px_per_m: 1.0 / 0.07e-3,
        angle_rad: 0.3,
        mirror: true,
        offset_px: [40.0, 200.0],
    };
    // FEM masks: an elongated ellipse growing with the step.
    let fem: Vec<_> = (1..=30)
        .map(|j| {
            let a = 0.2e-3 + 0.15e-3 * j as f64;
            let b = 0.05e-3 + 0.03e-3 * j as f64;
            mask_from_fn(gel_grid, |r, c| {
                let p = gel_grid.center(r, c);
                let (x, y) = (p[0] - 8e-3, p[1] - 6e-3);
                let (u, v) = (x * 0.8 + y * 0.6, -x * 0.6 + y * 0.8);
                (u / a).powi(2) + (v / b).powi(2) < 1.0
            })
        })
        .collect();
    // Real frame k shows FEM step k - 3.
    let offset = 3;
    let real_masks: Vec<_> = (0..=30)
        .map(|k| {
            if k > offset {
                real::warp_mask(&fem[k - offset - 1], &truth, 240, 320)
            } else {
                mask_from_fn(real::image_grid(240, 320), |_, _| false)
            }
        })
        .collect();
    let fit: Vec<usize> = (1..=30).filter(|k| k % 2 == 0).collect();
    let score: Vec<usize> = (1..=30).filter(|k| k % 2 == 1).collect();
    let f = real::fit_map(&real_masks, &fem, &fit, 1..=5, None, 1.0).unwrap();
    assert_eq!(f.offset_steps, offset);
    assert!(f.fit_iou > 0.95, "{}", f.fit_iou);
    let s = real::score_map(&real_masks, &fem, &f, &score).unwrap();
    let worst = s.iter().map(|m| m.iou).fold(1.0, f64::min);
    assert!(worst > 0.9, "{s:?}");
    // The ellipse is symmetric, so the map is determined up to the ellipse's own symmetries: check
    // where the ellipse centre lands and the scale.
    let c_true = truth.to_px([8e-3, 6e-3]);
    let c_fit = f.map.to_px([8e-3, 6e-3]);
    assert!((c_true[0] - c_fit[0]).hypot(c_true[1] - c_fit[1]) < 1.0);
    assert!((f.map.px_per_m / truth.px_per_m - 1.0).abs() < 0.03);

    // A few pixels of noise in a frame before the touch do not move the offsets searched:
    // the window is centred on the first frame with a real share of the contact.
    let mut noisy = real_masks.clone();
    let cols = noisy[2].grid.cols;
    for c in 100..103 {
        noisy[2].pixels[120 * cols + c] = true;
    }
    let pairs = real::MaskPairs {
        real: noisy,
        fem: fem.clone(),
        fit_frames: fit.clone(),
        score_frames: score.clone(),
        mask: MaskOptions::default(),
    };
    let (lo, hi) = pairs.offsets(1, 1.0).unwrap();
    assert!((lo..=hi).contains(&offset), "{lo}..={hi}");
    let f = pairs.fit(lo..=hi, None, 1.0).unwrap();
    assert_eq!(f.offset_steps, offset);
    let s = pairs.score(&f).unwrap();
    assert!(s.iter().all(|m| m.iou > 0.9), "{s:?}");

    // A scale that is known is kept: the true one fits as well as a free fit, a wrong one
    // (20 % too large) cannot reach it even though the step offset partly makes up for it.
    let held = pairs.fit(lo..=hi, Some(truth.px_per_m), 1.0).unwrap();
    assert_eq!(held.map.px_per_m, truth.px_per_m);
    // (frame 2's noise pixels cost every fit here one fitting pair: 1/15 of the mean)
    assert!(
        held.fit_iou >= f.fit_iou - 0.005,
        "{} against {}",
        held.fit_iou,
        f.fit_iou
    );
    let wrong = pairs.fit(lo..=hi, Some(1.2 * truth.px_per_m), 1.0).unwrap();
    assert_eq!(wrong.map.px_per_m, 1.2 * truth.px_per_m);
    assert!(
        wrong.fit_iou < held.fit_iou - 0.03,
        "{} against {}",
        wrong.fit_iou,
        held.fit_iou
    );
}

/// Real frames that are samples of a faster indentation (1.5 FEM steps per frame) are fitted
/// back at that rate with its offset, and at the rate the masks fit better than at one step
/// per frame with the best offset and map there; a rate that is not positive is refused.
#[test]
fn map_fit_recovers_the_steps_per_frame() {
    let gel_grid = gel_grid_240x320();
    let truth = CameraMap {
        px_per_m: 1.0 / 0.06e-3,
        angle_rad: -0.5,
        mirror: false,
        offset_px: [60.0, 150.0],
    };
    // FEM masks: an ellipse whose length grows as the square root of the step (a dome's
    // contact) and whose width grows linearly (a wedge's), so no scale or shift of one step
    // looks like another.
    let fem: Vec<_> = (1..=60)
        .map(|j| {
            let a = 0.5e-3 * (j as f64).sqrt();
            let b = 0.04e-3 * j as f64;
            mask_from_fn(gel_grid, |r, c| {
                let p = gel_grid.center(r, c);
                let (x, y) = (p[0] - 9e-3, p[1] - 7e-3);
                (x / a).powi(2) + (y / b).powi(2) < 1.0
            })
        })
        .collect();
    let (offset, rate) = (4, 1.5);
    let real_masks: Vec<_> = (0..=40)
        .map(|k| match real::paired_step(k, offset, rate) {
            j @ 1..=60 => real::warp_mask(&fem[j - 1], &truth, 240, 320),
            _ => mask_from_fn(real::image_grid(240, 320), |_, _| false),
        })
        .collect();
    let pairs = real::MaskPairs {
        real: real_masks,
        fem,
        fit_frames: (1..=40).filter(|k| k % 2 == 0).collect(),
        score_frames: (1..=40).filter(|k| k % 2 == 1).collect(),
        mask: MaskOptions::default(),
    };
    let fit_at = |r: f64| {
        let (lo, hi) = pairs.offsets(3, r).unwrap();
        pairs.fit(lo..=hi, Some(truth.px_per_m), r).unwrap()
    };
    let (at_rate, at_one) = (fit_at(rate), fit_at(1.0));
    assert_eq!(at_rate.offset_steps, offset);
    assert_eq!(at_rate.steps_per_frame, rate);
    assert!(at_rate.fit_iou > 0.95, "{}", at_rate.fit_iou);
    assert!(
        at_one.fit_iou < at_rate.fit_iou - 0.05,
        "one step per frame {} against {}",
        at_one.fit_iou,
        at_rate.fit_iou
    );
    let scored = pairs.score(&at_rate).unwrap();
    assert!(scored.iter().all(|m| m.iou > 0.9), "{scored:?}");
    // The odd frames are paired at the rate: frame 9 with step round(5 x 1.5) = 8.
    let f9 = scored.iter().find(|m| m.frame == 9).unwrap();
    assert_eq!(f9.fem_step, 8);
    for bad in [0.0, -1.0, f64::NAN] {
        let e = real::fit_map(&pairs.real, &pairs.fem, &pairs.fit_frames, 1..=5, None, bad)
            .unwrap_err()
            .to_string();
        assert!(e.contains("steps per real frame"), "{e}");
    }
}

/// The real calibration loads with its 125 bins; the real frames load at 240 x 320; the frame
/// before contact has an empty measured mask and the deepest a large one; the real sensor's
/// own background reproduces under the flat gel (checked above) and the renderer changes the
/// image only where the gel is pressed.
#[test]
fn real_frames_and_calibration() {
    let (Some(npz), Some(f0)) = (
        test_data("digit/optics/taxim_polycalib.npz"),
        test_data("digit/real-frames-edge6/edge6_00.jpg"),
    ) else {
        return;
    };
    let c = PolyCalib::from_npz(&npz).unwrap();
    assert_eq!(c.bins, 125);
    let frames = real::load_frames(f0.parent().unwrap(), "edge6").unwrap();
    assert_eq!(frames.len(), 100);
    let bg = &frames[0];
    let o = MaskOptions::default();
    let first = real::measured_mask(&frames[1], bg, &o).unwrap();
    let last = real::measured_mask(&frames[99], bg, &o).unwrap();
    assert_eq!(first.count(), 0);
    assert!(last.count() > 500, "{}", last.count());
}

/// Mesh -> image -> mesh: a smooth dimple on the coarse gel's top face, resampled onto the
/// 240 x 320 grid (`SurfaceSampler`) and back onto the top nodes (`GridToMesh`), returns the
/// nodal u_z to within the linear interpolation's error over one 62.5 um pixel.
#[test]
fn grid_to_mesh_round_trip_on_the_gel() {
    let Some(mesh) = test_data("digit/DIGIT_remesh2.vtk") else {
        return;
    };
    let gel = Gel::digit(&mesh, GelMaterial::default()).unwrap();
    let grid = Grid::for_gel(&gel);
    let map = CameraMap::for_grid(&grid);
    let s = SurfaceSampler::new(&gel, grid.rows, grid.cols, &map);
    let centre = grid.center(grid.rows / 2, grid.cols / 2);
    let u: Vec<[f64; 3]> = gel
        .mesh
        .points
        .iter()
        .map(|p| {
            let d2 = (p[0] - centre[0]).powi(2) + (p[1] - centre[1]).powi(2);
            [0.0, 0.0, -5e-4 * (-d2 / (4e-3f64).powi(2)).exp()]
        })
        .collect();
    let mut h = vec![0.0f32; grid.rows * grid.cols];
    s.heights(&u, &mut h).unwrap();
    let top: Vec<[f64; 3]> = gel.top.iter().map(|&i| gel.mesh.points[i]).collect();
    let g = GridToMesh::new(&top, grid.rows, grid.cols, &map).unwrap();
    let back = g.displacement(&h).unwrap();
    let (mut worst, mut sum) = (0.0f64, 0.0);
    for (k, &i) in gel.top.iter().enumerate() {
        let e = (back[k][2] - u[i][2]).abs();
        worst = worst.max(e);
        sum += e;
    }
    let mean = sum / top.len() as f64;
    // Slope at most 5e-4 / 4e-3 * 0.86 ~ 0.11: over half a pixel (31 um), ~3.4 um.
    assert!(
        worst < 4e-6 && mean < 1e-6,
        "worst {worst} m, mean {mean} m"
    );
}

/// `ocm tactile render` without `--map` frames the gel as the networks see it: the whole top
/// face inside the 240 x 320 image. The mask grid itself has rows along gel y (the 20 mm side)
/// and columns along gel x, so drawing it unrotated into a 240 x 320 image cut the DIGIT_v8
/// gel's last 80 rows (5 mm) off: the bug this guards against. Checked on both meshes: on
/// DIGIT_v8 the frame is exactly the networks' (0.0625 mm per pixel), on the coarse
/// DIGIT_remesh2 (a larger top face) the gel is scaled to fit.
#[test]
fn default_render_map_shows_the_whole_gel() {
    let (Some(fine), Some(coarse)) = (
        test_data("digit/DIGIT_v8.vtk"),
        test_data("digit/DIGIT_remesh2.vtk"),
    ) else {
        return;
    };
    let (rows, cols) = (real::ROWS, real::COLS);
    for (mesh, exact) in [(fine, true), (coarse, false)] {
        let gel = Gel::digit(&mesh, GelMaterial::default()).unwrap();
        let grid = Grid::for_gel(&gel);
        let map = camera::fit_landscape(&gel, rows, cols);
        let (net_map, r1, c1) = camera::landscape_map(&gel, 1);
        assert_eq!((r1, c1), (grid.cols, grid.rows));
        assert_eq!(map == net_map, exact, "{mesh:?}: {grid:?}");
        let mut covered_span = [[f64::INFINITY, f64::NEG_INFINITY]; 2];
        for &i in &gel.top {
            let q = map.to_px([gel.mesh.points[i][0], gel.mesh.points[i][1]]);
            // The grid rounds the top face to whole pixels (DIGIT_v8: 20.00001 mm).
            let inside = |v: f64, n: usize| (-1e-3..=n as f64 + 1e-3).contains(&v);
            assert!(
                inside(q[0], cols) && inside(q[1], rows),
                "node {i} at {q:?}"
            );
            for k in 0..2 {
                covered_span[k] = [covered_span[k][0].min(q[k]), covered_span[k][1].max(q[k])];
            }
        }
        // Fills the image along at least one side.
        let fill = (covered_span[0][1] - covered_span[0][0]) / cols as f64;
        let fill = fill.max((covered_span[1][1] - covered_span[1][0]) / rows as f64);
        assert!(fill > 0.99, "{mesh:?}: {covered_span:?}");
        let s = SurfaceSampler::new(&gel, rows, cols, &map);
        // DIGIT_remesh2's top face is not a full rectangle (90 % of its bounding box).
        let least = if exact { 97 } else { 88 };
        assert!(
            s.covered() > rows * cols * least / 100,
            "{mesh:?}: {}",
            s.covered()
        );
        if exact {
            // The old default, the mask grid drawn unrotated, left a quarter of the gel out.
            let old = SurfaceSampler::new(&gel, rows, cols, &CameraMap::for_grid(&grid));
            assert!(old.covered() < rows * cols * 80 / 100, "{}", old.covered());
        }
    }
}

/// The colour transform and depth shading: a renderer with a known transform M and depth gains
/// g renders background + M dS + g h (dS the identity renderer's change, within rounding), a
/// flat gel still renders the background, and `fit_colour` recovers M and g from such frames.
#[test]
fn colour_transform_and_depth_shading_are_recovered() {
    let (rows, cols) = (48, 64);
    let bg = uniform(rows, cols, [120, 110, 100]);
    let p = 62.5e-6;
    let plain = Renderer::new(bin_table(), &bg).unwrap();
    let m = [[0.5f32, 0.2, 0.0], [-0.1, 0.3, 0.0], [0.25, 0.0, 0.0]];
    let g = [-4.0e4f32, 1.0e4, -2.0e4];
    let mut tuned = plain.clone();
    tuned.colour = m;
    tuned.depth_gain = g;
    assert_eq!(tuned.render(&vec![0.0; rows * cols], p as f32).unwrap(), bg);
    let mut triples = Vec::new();
    let mut frames = Vec::new();
    for (k, depth) in [2e-4, 4e-4, 6e-4].into_iter().enumerate() {
        let (h, _) = dimple(rows, cols, p, 2e-3 + k as f64 * 1e-3, depth);
        let base = plain.render(&h, p as f32).unwrap();
        let got = tuned.render(&h, p as f32).unwrap();
        for (i, &hi) in h.iter().enumerate() {
            for ch in 0..3 {
                let ds: Vec<f32> = (0..3)
                    .map(|j| f32::from(base.data[i * 3 + j]) - f32::from(bg.data[i * 3 + j]))
                    .collect();
                let want = f32::from(bg.data[i * 3 + ch])
                    + (0..3).map(|j| m[ch][j] * ds[j]).sum::<f32>()
                    + g[ch] * hi;
                let want = want.clamp(0.0, 255.0);
                // The identity renderer's change was rounded: M spreads 0.5 over the row.
                let tol = 0.5 * m[ch].iter().map(|v| v.abs()).sum::<f32>() + 0.51;
                let v = f32::from(got.data[i * 3 + ch]);
                assert!((v - want).abs() <= tol, "pixel {i} ch {ch}: {v} vs {want}");
            }
        }
        frames.push(got);
        triples.push((base, h));
    }
    let t: Vec<(RgbImage, &RgbImage, Vec<f32>)> = triples
        .into_iter()
        .zip(&frames)
        .map(|((base, h), f)| (base, f, h))
        .collect();
    let (mf, gf) = real::fit_colour(&t, &bg);
    for ch in 0..3 {
        for j in 0..3 {
            assert!((mf[ch][j] - f64::from(m[ch][j])).abs() < 0.03, "{mf:?}");
        }
        assert!(
            (gf[ch] - f64::from(g[ch])).abs() < 0.05 * 4e4,
            "{gf:?} vs {g:?}"
        );
    }
}

/// `real::compare` end to end on frames rendered from its own fields: a known L-shaped dimple
/// (three bumps of unequal depth, so no rotation or mirror maps the contact onto itself) on a
/// box gel, rendered through a known camera map with a known step offset, colour transform and
/// depth shading (10 grey levels at 30 um, so the image mask and the FEM mask nearly agree),
/// stands in for the real frames. The comparison must find the offset, put the dimple where
/// the map put it, and re-render the scored frames close to the "real" ones, far closer than
/// the background alone (measured: PSNR 47 dB against 27.5, contact SSIM 0.982 against 0.816,
/// mask IoU 0.93).
#[test]
fn compare_matches_frames_rendered_from_its_own_fields() {
    let mesh = ocm_fem::mesh::generate::box_mesh([24, 30, 4], [12e-3, 15e-3, 2e-3]);
    let base = 0.5e-3;
    let gel = Gel::from_mesh(mesh, GelMaterial::default(), base).unwrap();
    let free = gel.z_top - base;
    let bumps = [
        ([5.5e-3, 7.0e-3], 1.0, 1.2e-3),
        ([7.8e-3, 7.0e-3], 0.7, 0.9e-3),
        ([5.5e-3, 9.0e-3], 0.5, 0.8e-3),
    ];
    let steps = 30;
    let fields: Vec<Vec<[f64; 3]>> = (1..=steps)
        .map(|j| {
            let depth = 15e-6 * j as f64;
            gel.mesh
                .points
                .iter()
                .map(|p| {
                    let uz: f64 = bumps
                        .iter()
                        .map(|(c, w, s)| {
                            let d2 = (p[0] - c[0]).powi(2) + (p[1] - c[1]).powi(2);
                            w * (-d2 / (s * s)).exp()
                        })
                        .sum();
                    let share = ((p[2] - base) / free).max(0.0);
                    [0.0, 0.0, -depth * uz * share]
                })
                .collect()
        })
        .collect();
    let (rows, cols) = (120, 160);
    let bg = RgbImage {
        rows,
        cols,
        data: (0..rows * cols)
            .flat_map(|i| {
                let (r, c) = (i / cols, i % cols);
                [200 + (r / 8) as u8, 190 + (c / 10) as u8, 180]
            })
            .collect(),
    };
    let truth = CameraMap {
        px_per_m: 1.0 / 0.08e-3,
        angle_rad: 0.4,
        mirror: false,
        offset_px: [20.0, -30.0],
    };
    let mut made = Renderer::new(bin_table(), &bg).unwrap();
    // Darkening with depth sets the measured contact: 10 grey levels (the mask threshold) at
    // 30 um, the FEM mask's level; the slopes tint it.
    made.colour = [[0.1, 0.05, 0.0], [0.0, 0.1, 0.0], [0.05, 0.0, 0.1]];
    made.depth_gain = [-10.0 / 30e-6; 3];
    let sampler = SurfaceSampler::new(&gel, rows, cols, &truth);
    let offset = 4;
    let frames: Vec<RgbImage> = (0..=steps + offset)
        .map(|k| {
            real::render_paired(&made, &sampler, &fields, real::paired_step(k, offset, 1.0))
                .unwrap()
        })
        .collect();
    let mut renderer = Renderer::new(bin_table(), &bg).unwrap();
    let opts = real::CompareOptions {
        offset_window: 3,
        ..real::CompareOptions::default()
    };
    let c = real::compare(&gel, &fields, &frames, &mut renderer, &opts, &mut |_| {}).unwrap();
    assert_eq!(c.fit.offset_steps, offset);
    assert!(c.fit.fit_iou > 0.85, "{}", c.fit.fit_iou);
    // the deepest bump's centre lands where the true map puts it
    let (t, f) = (truth.to_px(bumps[0].0), c.fit.map.to_px(bumps[0].0));
    assert!((t[0] - f[0]).hypot(t[1] - f[1]) < 3.0, "{t:?} vs {f:?}");
    assert!((c.fit.map.px_per_m / truth.px_per_m - 1.0).abs() < 0.05);
    assert!(!c.fit.map.mirror && (c.fit.map.angle_rad - truth.angle_rad).abs() < 0.1);
    let med = |v: Vec<f64>| {
        let mut v = v;
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let psnr = med(c.render.iter().map(|r| r.psnr_db).collect());
    let psnr_bg = med(c.background_only.iter().map(|r| r.psnr_db).collect());
    let contact = |v: &[real::RenderScore]| med(v.iter().filter_map(|r| r.contact_ssim).collect());
    let (ssim, ssim_bg) = (contact(&c.render), contact(&c.background_only));
    let iou = med(c.masks.iter().map(|m| m.iou).collect());
    assert!(iou > 0.9, "{:?}", c.masks);
    assert!(psnr > 40.0 && psnr > psnr_bg + 10.0, "{psnr} vs {psnr_bg}");
    assert!(ssim > 0.97 && ssim > ssim_bg + 0.1, "{ssim} vs {ssim_bg}");
}
