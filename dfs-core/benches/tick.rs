//! Benchmark of the DFS tick (placeholder until the tick benchmark lands).

fn main() {}
