//! Proximal maps: total variation by Haar shrinkage ([`tv`]) or exactly by its dual
//! ([`tv_dual`], on the gradient operator of [`grad3`]), with non-negativity.

pub mod grad3;
pub mod tv;
pub mod tv_dual;
