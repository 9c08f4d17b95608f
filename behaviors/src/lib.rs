//! Behaviour engine.
