//! Checkpoints: a model's weights with the architecture, configuration and scaling that give
//! them meaning, guarded by checksums.
//!
//! File layout (all integers little-endian):
//!
//! | bytes | content |
//! |-------|---------|
//! | 8     | magic `OCMLCKPT` |
//! | 4     | format version |
//! | 8     | header length `h` |
//! | 8     | CRC-64/XZ of the header |
//! | h     | header, JSON ([`CheckpointHeader`]) |
//! | rest  | weights (burnpack bytes), length and CRC-64 in the header |

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use burn::module::{Module, ModuleVisitor, Param};
use burn::store::ModuleRecord;
use burn::tensor::{Bytes, Tensor};
use serde::{Deserialize, Serialize};

use crate::error::{LearnError, Result};
use crate::scaling::Standardizer;

const MAGIC: &[u8; 8] = b"OCMLCKPT";
const FORMAT_VERSION: u32 = 1;
const CRC64: crc::Crc<u64> = crc::Crc::<u64>::new(&crc::CRC_64_XZ);

/// Name and shape of one parameter tensor, in declaration order.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ParamShape {
    /// Dotted path of the parameter inside the model (`layers.0.weight`).
    pub path: String,
    /// Tensor shape.
    pub shape: Vec<usize>,
}

/// Everything in a checkpoint except the weights.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CheckpointHeader {
    /// Name of the architecture (`dynamics.forward`, `mlp`, ...).
    pub architecture: String,
    /// The architecture's configuration, as its own JSON.
    pub config: serde_json::Value,
    /// Scalers of the inputs and outputs, by role (`input`, `target`, ...).
    pub scalers: BTreeMap<String, Standardizer>,
    /// Free-form facts about the run (seed, epochs, data set, final losses).
    pub meta: serde_json::Value,
    /// The model's parameter tensors.
    pub params: Vec<ParamShape>,
    /// Length of the weight payload in bytes.
    pub payload_bytes: u64,
    /// CRC-64/XZ of the weight payload.
    pub payload_crc64: u64,
}

/// The parameter tensors of `model`, by path and shape.
pub fn param_shapes<M: Module>(model: &M) -> Vec<ParamShape> {
    let mut v = ShapeVisitor::default();
    model.visit(&mut v);
    v.out
}

#[derive(Default)]
struct ShapeVisitor {
    path: Vec<String>,
    out: Vec<ParamShape>,
}

impl ModuleVisitor for ShapeVisitor {
    fn enter_module(&mut self, name: &str, _container_type: &str) {
        self.path.push(name.to_string());
    }

    fn exit_module(&mut self, _name: &str, _container_type: &str) {
        self.path.pop();
    }

    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        self.out.push(ParamShape {
            path: self.path.join("."),
            shape: param.lazy_shape().to_vec(),
        });
    }
}

/// What to write beside the weights.
#[derive(Debug, Clone)]
pub struct CheckpointInfo<'a, C: Serialize> {
    /// Architecture name.
    pub architecture: &'a str,
    /// The architecture's configuration.
    pub config: &'a C,
    /// Input/output scalers by role.
    pub scalers: BTreeMap<String, Standardizer>,
    /// Free-form facts about the run.
    pub meta: serde_json::Value,
}

/// Writes `model` with its description to `path`.
pub fn save_checkpoint<M: Module, C: Serialize>(
    path: &Path,
    model: &M,
    info: &CheckpointInfo<'_, C>,
) -> Result<()> {
    let params = param_shapes(model);
    let payload = model
        .clone()
        .into_record()
        .into_bytes()
        .map_err(|e| LearnError::Data(format!("cannot serialise the weights: {e:?}")))?;
    let payload: &[u8] = &payload;
    let config = serde_json::to_value(info.config)
        .map_err(|e| LearnError::Config(format!("configuration is not serialisable: {e}")))?;
    let header = CheckpointHeader {
        architecture: info.architecture.to_string(),
        config,
        scalers: info.scalers.clone(),
        meta: info.meta.clone(),
        params,
        payload_bytes: payload.len() as u64,
        payload_crc64: CRC64.checksum(payload),
    };
    let header_json = serde_json::to_vec_pretty(&header)
        .map_err(|e| LearnError::Data(format!("cannot serialise the header: {e}")))?;
    let mut bytes = Vec::with_capacity(28 + header_json.len() + payload.len());
    bytes.extend_from_slice(MAGIC);
    bytes.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
    bytes.extend_from_slice(&(header_json.len() as u64).to_le_bytes());
    bytes.extend_from_slice(&CRC64.checksum(&header_json).to_le_bytes());
    bytes.extend_from_slice(&header_json);
    bytes.extend_from_slice(payload);
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|e| LearnError::io(dir, e))?;
    }
    // Write then rename, so that a crash never leaves a half-written checkpoint under the name.
    let tmp = path.with_extension("tmp");
    std::fs::write(&tmp, &bytes).map_err(|e| LearnError::io(&tmp, e))?;
    std::fs::rename(&tmp, path).map_err(|e| LearnError::io(path, e))
}

/// A checkpoint read and verified, its weights not yet applied to a model.
#[derive(Debug, Clone)]
pub struct Checkpoint {
    /// Where it was read from.
    pub path: PathBuf,
    /// Its description.
    pub header: CheckpointHeader,
    payload: Vec<u8>,
}

impl Checkpoint {
    /// Reads `path` and verifies magic, version and both checksums.
    pub fn read(path: &Path) -> Result<Self> {
        let bytes = std::fs::read(path).map_err(|e| LearnError::io(path, e))?;
        let corrupt = |reason: String| LearnError::CorruptCheckpoint {
            path: path.to_path_buf(),
            reason,
        };
        if bytes.len() < 8 || &bytes[..8] != MAGIC {
            return Err(corrupt("not an ocm checkpoint (bad magic)".into()));
        }
        if bytes.len() < 28 {
            return Err(corrupt(format!(
                "file is {} bytes, shorter than the 28-byte preamble",
                bytes.len()
            )));
        }
        let word = |r: std::ops::Range<usize>| -> [u8; 8] {
            let mut w = [0u8; 8];
            w.copy_from_slice(&bytes[r]);
            w
        };
        let version = u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]);
        if version != FORMAT_VERSION {
            return Err(corrupt(format!(
                "format version {version}, this build reads {FORMAT_VERSION}"
            )));
        }
        let header_len = u64::from_le_bytes(word(12..20));
        let header_crc = u64::from_le_bytes(word(20..28));
        let header_end = usize::try_from(header_len)
            .ok()
            .and_then(|h| h.checked_add(28))
            .filter(|&e| e <= bytes.len())
            .ok_or_else(|| corrupt(format!("header length {header_len} exceeds the file")))?;
        let header_json = &bytes[28..header_end];
        if CRC64.checksum(header_json) != header_crc {
            return Err(corrupt("header checksum mismatch".into()));
        }
        let header: CheckpointHeader = serde_json::from_slice(header_json)
            .map_err(|e| corrupt(format!("header is not valid: {e}")))?;
        let payload = bytes[header_end..].to_vec();
        if payload.len() as u64 != header.payload_bytes {
            return Err(corrupt(format!(
                "weights are {} bytes, the header says {}",
                payload.len(),
                header.payload_bytes
            )));
        }
        if CRC64.checksum(&payload) != header.payload_crc64 {
            return Err(corrupt("weights checksum mismatch".into()));
        }
        Ok(Self {
            path: path.to_path_buf(),
            header,
            payload,
        })
    }

    /// The architecture's configuration, decoded.
    pub fn config<C: serde::de::DeserializeOwned>(&self) -> Result<C> {
        serde_json::from_value(self.header.config.clone()).map_err(|e| {
            LearnError::CheckpointMismatch {
                path: self.path.clone(),
                reason: format!(
                    "configuration of '{}' does not decode: {e}",
                    self.header.architecture
                ),
            }
        })
    }

    /// [`Self::config`], once the checkpoint is known to hold one of `architectures`: a file of
    /// another kind (an RL policy given where an NPE is expected) is named as that, not as a
    /// configuration that does not decode.
    pub fn config_of<C: serde::de::DeserializeOwned>(&self, architectures: &[&str]) -> Result<C> {
        if !architectures.contains(&self.header.architecture.as_str()) {
            return Err(LearnError::CheckpointMismatch {
                path: self.path.clone(),
                reason: format!(
                    "holds a '{}' model, expected {}",
                    self.header.architecture,
                    architectures
                        .iter()
                        .map(|a| format!("'{a}'"))
                        .collect::<Vec<_>>()
                        .join(" or ")
                ),
            });
        }
        self.config()
    }

    /// The scaler stored under `role`.
    pub fn scaler(&self, role: &str) -> Result<&Standardizer> {
        self.header
            .scalers
            .get(role)
            .ok_or_else(|| LearnError::CheckpointMismatch {
                path: self.path.clone(),
                reason: format!("no '{role}' scaler stored"),
            })
    }

    /// Loads the weights into `model`, which must be of `architecture` with `config` and have
    /// exactly the stored parameter shapes.
    pub fn load_into<M: Module, C: Serialize>(
        &self,
        model: M,
        architecture: &str,
        config: &C,
    ) -> Result<M> {
        let mismatch = |reason: String| LearnError::CheckpointMismatch {
            path: self.path.clone(),
            reason,
        };
        if self.header.architecture != architecture {
            return Err(mismatch(format!(
                "holds a '{}' model, expected '{architecture}'",
                self.header.architecture
            )));
        }
        let expected = serde_json::to_value(config)
            .map_err(|e| LearnError::Config(format!("configuration is not serialisable: {e}")))?;
        if expected != self.header.config {
            return Err(mismatch(format!(
                "configuration differs: stored {}, expected {expected}",
                self.header.config
            )));
        }
        let shapes = param_shapes(&model);
        if shapes != self.header.params {
            let first = shapes
                .iter()
                .zip(&self.header.params)
                .find(|(a, b)| a != b)
                .map(|(a, b)| {
                    format!(
                        "{} {:?} vs stored {} {:?}",
                        a.path, a.shape, b.path, b.shape
                    )
                })
                .unwrap_or_else(|| {
                    format!(
                        "{} parameters vs {} stored",
                        shapes.len(),
                        self.header.params.len()
                    )
                });
            return Err(mismatch(format!("parameter shapes differ: {first}")));
        }
        let record = ModuleRecord::from_bytes(Bytes::from_bytes_vec(self.payload.clone()))
            .map_err(|e| LearnError::CorruptCheckpoint {
                path: self.path.clone(),
                reason: format!("weights do not decode: {e:?}"),
            })?;
        model
            .try_load_record(record)
            .map_err(|e| mismatch(format!("weights do not fit the model: {e:?}")))
    }
}
