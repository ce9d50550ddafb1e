//! Seeded parameter initialisation.
//!
//! burn draws initial weights from one process-wide generator, so two models built in parallel
//! test threads would steal numbers from each other. Every model here is instead re-initialised
//! from its own ChaCha stream, walking the parameters in their fixed declaration order.

use burn::module::{Module, ModuleMapper, Param};
use burn::tensor::{Tensor, TensorData};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Re-initialises every weight and bias of `module` from `seed`; normalisation scales and
/// shifts keep their constant defaults (ones and zeros).
///
/// Weights (rank >= 2) are drawn from `U(-k, k)` with `k = 1/sqrt(fan_in)`, biases are zero.
/// A linear weight is stored `[d_in, d_out]`; a convolution weight `[c_out, c_in, k...]`.
pub fn seeded_init<M: Module>(module: M, seed: u64) -> M {
    let mut mapper = SeededInit {
        rng: ChaCha8Rng::seed_from_u64(seed),
        path: Vec::new(),
    };
    module.map(&mut mapper)
}

struct SeededInit {
    rng: ChaCha8Rng,
    path: Vec<String>,
}

impl ModuleMapper for SeededInit {
    fn enter_module(&mut self, name: &str, _container_type: &str) {
        self.path.push(name.to_string());
    }

    fn exit_module(&mut self, _name: &str, _container_type: &str) {
        self.path.pop();
    }

    fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
        let name = self.path.last().map(String::as_str).unwrap_or("");
        let is_norm = matches!(name, "gamma" | "beta");
        if is_norm {
            return param;
        }
        let rng = &mut self.rng;
        param.map(|t| {
            let dims = t.dims();
            let n: usize = dims.iter().product();
            let values: Vec<f32> = if D >= 2 && name != "bias" {
                let fan_in = if D == 2 {
                    dims[0]
                } else {
                    dims[1..].iter().product::<usize>()
                };
                let k = 1.0 / (fan_in.max(1) as f64).sqrt();
                (0..n).map(|_| rng.random_range(-k..k) as f32).collect()
            } else {
                vec![0.0; n]
            };
            let fresh = Tensor::<D>::from_data(TensorData::new(values, dims), &t.device());
            if t.is_require_grad() {
                fresh.require_grad()
            } else {
                fresh
            }
        })
    }
}
