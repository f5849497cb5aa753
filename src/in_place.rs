//! Construction in place of the states too large for the stack.
//!
//! The drive stage's state ([`crate::node::drive::Drive`], 35 KiB with the controller) is more
//! than the firmware's 16 KiB stack holds, so it cannot be built as a value and moved into its
//! static; a `static` initialised with the `const fn new()` keeps a copy of its initial bytes in
//! flash (`.data`: the whole state, 35 KiB of the 192 KiB budget, though almost all of it is
//! zero). `Drive::init` instead builds it where it lives, in uninitialised RAM: every field
//! written once through a raw pointer, the arrays an element at a time, so that nothing larger
//! than one element passes through the stack and nothing of it is stored in flash. The values
//! are those of the `const fn new()`s (`node::drive`'s tests compare the two).
//!
//! The only `unsafe` code of the core is here and in the `init_in_place` functions that use it
//! (`node::drive`, `control::planner`, `control::path`, `control::mpc`); each writes every field
//! of its type exactly once before the value is used.

/// Writes `value` into each element of the array at `slot`.
///
/// # Safety
///
/// `slot` must be valid for writes of a `[T; N]` and aligned for it.
pub(crate) unsafe fn fill<T: Copy, const N: usize>(slot: *mut [T; N], value: T) {
    let first = slot.cast::<T>();
    for i in 0..N {
        // SAFETY: `i < N`: an element of the array the caller vouches for.
        unsafe { first.add(i).write(value) };
    }
}
