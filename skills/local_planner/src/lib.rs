//! Local ground planner: panorama terrain analysis, reachability scan, local goal, DWA.
