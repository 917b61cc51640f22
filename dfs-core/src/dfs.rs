//! The DFS tick (paper Fig. 6).
