//! Which pixels of the solved grid the data term keeps, and how.

/// What the data term does with each pixel of the solved grid: left out (`mask` 0) or
/// one-sided (`lower_bounds`); `None` fields: every pixel is a plain equality.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DataMask {
    pub mask: Option<Vec<f32>>,
    pub lower_bounds: Option<Vec<bool>>,
}
