//! Criterion benchmarks of the protocol core (placeholder until the benches land).
fn main() {}
