//! catmodel automation (in progress).
fn main() {}
