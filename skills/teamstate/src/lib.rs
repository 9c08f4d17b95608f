//! Replicated team database with priorities and deterministic merge rules, transport-free.
