//! The number type the energy model is written in: plain `f64` for values,
//! forward-mode dual numbers (`num-dual`) for exact derivatives.

use num_dual::{DualNum, DualStruct};

/// A real number or a dual number over `f64`; the model code is generic over
/// it so one implementation yields values, gradients and Hessians.
pub trait Scalar: DualNum<Primitive = f64> + DualStruct<Real = f64> + Copy {
    /// The real (value) part.
    fn value(&self) -> f64 {
        self.re()
    }
}

impl<T: DualNum<Primitive = f64> + DualStruct<Real = f64> + Copy> Scalar for T {}
