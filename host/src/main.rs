//! `catmodel`: the host command-line tool (see README).
fn main() {
    println!("catmodel {}", env!("CARGO_PKG_VERSION"));
}
