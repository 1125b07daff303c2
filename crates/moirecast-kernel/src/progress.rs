//! Progress reporting without I/O: the kernel announces stages and ticks,
//! the binary draws them.

pub trait Progress: Sync {
    /// A new stage with `total` units of work.
    fn stage(&self, _name: &'static str, _total: u64) {}
    /// `n` more units done in the current stage.
    fn tick(&self, _n: u64) {}
    /// Whether the work is no longer wanted: the mesher then stops at its
    /// next stage with [`crate::KernelError::Cancelled`] (the studio's
    /// build of a revision a newer one replaced).
    fn cancelled(&self) -> bool {
        false
    }
}

/// Reports nothing.
pub struct Silent;
impl Progress for Silent {}
