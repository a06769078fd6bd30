//! The imaging model and the physics behind it: the operator and its adjoint, the
//! sequence operator, and the continuous-time simulation agreeing with the model.
//! One test binary (`cargo test --test model`); each module is one theme.

#[path = "../support/mod.rs"]
mod support;

mod properties;
mod sequence_operator;
mod sim_demo_size;
mod sim_model_agreement;
