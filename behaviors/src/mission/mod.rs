//! The mission language: YAML files → typed mission + compiled behaviour trees, with staged
//! validation whose every error names the file, line, column and node.

pub mod build;
pub mod checks;
pub mod compile;
pub mod diagnostic;
pub mod json_schema;
pub mod limits;
pub mod load;
pub mod operator_script;
pub mod output;
pub mod schema;
pub mod tree;
pub mod yaml;

pub use build::{BuildError, BuildOptions, build_executor, build_tree};
pub use checks::{RobotChecks, RobotProblem};
pub use diagnostic::{Diagnostic, Rendered, Severity, Stage};
pub use load::{
    CompiledRole, LoadOptions, LoadedMission, PROVIDED_ENTRIES, check_endpoint, load_mission, load_mission_str,
    load_mission_with, skills_of,
};
pub use schema::MissionFile;
pub use tree::{TreeNode, load_tree_str};
