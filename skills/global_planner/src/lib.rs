//! Global ground planner: traversability graph, learned traversability, experience updates, search.
