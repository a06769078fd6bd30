//! Proximal maps: total variation by Haar shrinkage ([`tv`]) or exactly by its dual
//! ([`tv_dual`], on the gradient operator of [`grad3`]), with non-negativity; sparsity (L1) beside them ([`sparse`]); the static + dynamic
//! model's block maps and exact joint non-negativity ([`static_dynamic`]).

pub mod grad3;
pub mod sparse;
pub mod static_dynamic;
pub mod tv;
pub mod tv_dual;
