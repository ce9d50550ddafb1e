//! Sharded datasets: byte-identical to an unsharded run, resumable, validated on read, readable by numpy.

use ocm_mor::dataset::{self, DatasetSpec, ModelKind};
use ocm_mor::drive::{DriveConfig, Input};
use ocm_mor::xs::XS_DIM;
use std::path::{Path, PathBuf};

/// A deterministic stand-in for a simulator: X_S integrates the inputs (the file logic under test
/// does not care where the numbers come from; the reduced model's own tests cover it).
fn integrate(inputs: &[Input]) -> ocm_mor::Result<Vec<[f64; 2 * XS_DIM]>> {
    let mut acc = [0.0; 2 * XS_DIM];
    Ok(inputs
        .iter()
        .map(|i| {
            for k in 0..3 {
                acc[k] += 0.01 * i.pressure_kpa[k];
                acc[3 + k] += 0.01 * i.tip_force_n[k];
            }
            acc[XS_DIM..XS_DIM + 3].copy_from_slice(&i.pressure_kpa);
            acc
        })
        .collect())
}

fn spec(seed: u64) -> DatasetSpec {
    DatasetSpec {
        model: ModelKind::Reduced,
        model_hash: "m".repeat(64),
        basis_hash: Some("b".repeat(64)),
        samples: 95,
        sequence_steps: 20,
        seed,
        drive: DriveConfig::default(),
    }
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("ocm-mor-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

fn write_all(dir: &Path, shards: usize, calls: &mut usize) {
    for i in 0..shards {
        dataset::write_shard(
            dir,
            &spec(7),
            i,
            shards,
            &mut |inp| {
                *calls += 1;
                integrate(inp)
            },
            &mut |_, _| {},
        )
        .unwrap();
    }
}

fn data_bytes(path: &Path) -> Vec<u8> {
    let b = std::fs::read(path).unwrap();
    let hl = u16::from_le_bytes([b[8], b[9]]) as usize;
    b[10 + hl..].to_vec()
}

#[test]
fn shards_concatenate_to_the_unsharded_run_and_reruns_skip() {
    let (one, three) = (tmp("one"), tmp("three"));
    let mut calls = 0;
    write_all(&one, 1, &mut calls);
    assert_eq!(calls, 5, "95 samples in sequences of 20");
    calls = 0;
    write_all(&three, 3, &mut calls);
    assert_eq!(calls, 5);
    for arr in dataset::array_specs() {
        let whole = data_bytes(&dataset::shard_dir(&one, 0, 1).join(&arr.file));
        let joined: Vec<u8> = (0..3)
            .flat_map(|i| data_bytes(&dataset::shard_dir(&three, i, 3).join(&arr.file)))
            .collect();
        assert!(whole == joined, "{} differs", arr.file);
    }
    let a = dataset::read(&one, Some(&"b".repeat(64))).unwrap();
    let b = dataset::read(&three, None).unwrap();
    assert_eq!(a.arrays, b.arrays);
    assert_eq!(a.arrays[1].len(), 95);
    // A rerun finds every shard complete and simulates nothing.
    calls = 0;
    write_all(&three, 3, &mut calls);
    assert_eq!(calls, 0);
    // A different dataset in the same folder is refused, naming the manifest and the field.
    let e = dataset::write_shard(&three, &spec(8), 0, 3, &mut integrate, &mut |_, _| {})
        .unwrap_err()
        .to_string();
    assert!(e.contains("manifest.json") && e.contains("seed"), "{e}");
    std::fs::remove_dir_all(&one).ok();
    std::fs::remove_dir_all(&three).ok();
}

#[test]
fn corrupt_or_mismatched_files_are_rejected_with_the_file_and_the_problem() {
    let dir = tmp("corrupt");
    let mut calls = 0;
    write_all(&dir, 2, &mut calls);
    let xs = dataset::shard_dir(&dir, 1, 2).join("xs.npy");
    let good = std::fs::read(&xs).unwrap();
    // Truncated.
    std::fs::write(&xs, &good[..good.len() - 13]).unwrap();
    let e = dataset::read(&dir, None).unwrap_err().to_string();
    assert!(e.contains("xs.npy") && e.contains("truncated"), "{e}");
    // Wrong shape in the header (same byte count: 8 columns read as 4 with twice the rows).
    let a = ocm_fem::npy::parse_f64_2d(&good, "x").unwrap();
    let mut b = vec![];
    ocm_fem::npy::write_f64_2d(&mut b, &a.data, a.rows * 2, 4).unwrap();
    std::fs::write(&xs, &b).unwrap();
    let e = dataset::read(&dir, None).unwrap_err().to_string();
    assert!(e.contains("xs.npy") && e.contains("shape"), "{e}");
    // Same shape, other values.
    let mut c = good.clone();
    let n = c.len();
    c[n - 1] ^= 0x40;
    std::fs::write(&xs, &c).unwrap();
    let e = dataset::read(&dir, None).unwrap_err().to_string();
    assert!(e.contains("xs.npy") && e.contains("SHA-256"), "{e}");
    std::fs::write(&xs, &good).unwrap();
    dataset::read(&dir, None).unwrap();
    // Another basis.
    let e = dataset::read(&dir, Some(&"c".repeat(64)))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("manifest.json") && e.contains("basis hash"),
        "{e}"
    );
    // Counts that do not fit together (each shard's rows are derived from them).
    let mpath = dir.join("manifest.json");
    let good_manifest = std::fs::read_to_string(&mpath).unwrap();
    let mut m: serde_json::Value = serde_json::from_str(&good_manifest).unwrap();
    m["samples"] = serde_json::json!(0);
    std::fs::write(&mpath, m.to_string()).unwrap();
    let e = dataset::read(&dir, None).unwrap_err().to_string();
    assert!(
        e.contains("manifest.json") && e.contains("samples 0") && e.contains("do not fit"),
        "{e}"
    );
    std::fs::write(&mpath, good_manifest).unwrap();
    // An unfinished shard.
    std::fs::remove_file(dataset::shard_dir(&dir, 0, 2).join("shard.json")).unwrap();
    let e = dataset::read(&dir, None).unwrap_err().to_string();
    assert!(e.contains("shard.json") && e.contains("unfinished"), "{e}");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn numpy_opens_the_arrays_with_the_manifest_shapes() {
    // The interpreter of the README's test command (its virtual environment), with numpy.
    let Some(python) = ocm_datadir::require_python(&["numpy"]) else {
        return;
    };
    let dir = tmp("numpy");
    let mut calls = 0;
    write_all(&dir, 2, &mut calls);
    let script = r#"
import json, sys, os, numpy as np
d = sys.argv[1]
m = json.load(open(os.path.join(d, "manifest.json")))
total = 0
for s in range(m["shards"]):
    sd = os.path.join(d, "shard-%04d-of-%04d" % (s, m["shards"]))
    rec = json.load(open(os.path.join(sd, "shard.json")))
    for arr in m["arrays"]:
        a = np.load(os.path.join(sd, arr["file"]))
        assert a.dtype == np.float64, a.dtype
        assert a.shape == (rec["rows"], len(arr["columns"])), (arr["file"], a.shape)
    t = np.load(os.path.join(sd, "time_s.npy"))
    assert np.all(t > 0)
    total += rec["rows"]
assert total == m["samples"], total
print("ok", total)
"#;
    let out = std::process::Command::new(&python)
        .args(["-c", script, dir.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "numpy check failed: {}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(String::from_utf8_lossy(&out.stdout).contains("ok 95"));
    std::fs::remove_dir_all(&dir).ok();
}
