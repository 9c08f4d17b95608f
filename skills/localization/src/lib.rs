//! Cross-view semantic localizer: particle filter against the aerial semantic map.
