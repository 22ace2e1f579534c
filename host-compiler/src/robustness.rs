//! Robustness of sampled trajectories: safety robustness (Theorem 4.7) and MTL robust semantics (Def 2.17).
