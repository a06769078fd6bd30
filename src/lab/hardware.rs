//! The one mapping between the hardware crate's types and the model's.
