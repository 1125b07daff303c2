//! Which array a family of lens surfaces belongs to: a leaf, so that the
//! error type can name it without importing the lens families.

/// Which array a family of lens surfaces belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Array {
    Revealer,
    Base,
}
