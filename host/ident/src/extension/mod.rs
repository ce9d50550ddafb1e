//! Model extensions, one per cause, fitted jointly with the baseline's free coefficients on the
//! training rows. All but latency are linear in their parameters (features computed from the
//! inputs, the baseline and causal operators); latency searches a small grid of dead times and
//! first-order lag constants applied to the baseline's output.

mod dynamic_features;
mod features;
mod in_loop;
mod joint_fit;
mod loop_signal;
mod prepared;
mod refined;

pub use features::{Features, LAGUERRE_FILTERS};
pub use joint_fit::SetFit;
pub use prepared::{ChannelFit, Prepared, channel_scale};
