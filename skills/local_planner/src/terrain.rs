//! Terrain analysis of a depth panorama (paper §Local Ground Planner): hole filling, projection,
//! gradients, obstacles, distance transform (Algorithm 1), reachability scan S(φ).

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use spomp_core::{DepthPanorama, PanoramaGeometry, Pose2, ReachabilityScan, RobotId, Time};

use crate::error::{ParamsError, TerrainError, non_negative, positive};
use crate::stages::{self, DistanceScratch, GradientScratch, GradientWindow, ReachScratch, Tables};

/// Parameters of terrain analysis. Defaults are the real-robot values (docs/design.md §5; where the
/// paper gives none, the authors' launch file); [`TerrainParams::simulation`] gives the
/// simulation values. The local planner README's table says where each rule comes from.
///
/// [`TerrainParams::validate`] states each field's valid range; a mission's parameter errors
/// come from there.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct TerrainParams {
    /// D_m: largest hole along a row that is filled by interpolation, metres of arc (default
    /// 0.1; finite, ≥ 0).
    pub hole_fill_max_m: f64,
    /// W: metric size of the gradient windows, metres (default 0.5; finite, > 0).
    pub gradient_window_m: f64,
    /// W_max as a fraction of the panorama width A (paper: A/5), so W_max = fraction·A pixels
    /// (default 0.2; finite, in (0, 1]).
    pub gradient_window_max_fraction: f64,
    /// h_s: height of the sensor above flat ground, metres; sets the elevation window w_e of
    /// the rows below the horizon (default 0.4; finite, > 0).
    pub sensor_height_m: f64,
    /// η: order of the range noise, metres; η·|sin θ| is subtracted from height differences,
    /// η_xy = η·cos θ added to horizontal-range differences (default 0.05; finite, ≥ 0).
    pub range_noise_m: f64,
    /// ∇_thresh: gradient magnitude (rise over run) above which a pixel is an obstacle
    /// (default 0.3, simulation 0.25; finite, > 0).
    pub slope_threshold: f64,
    /// Obstacle runs along a row (with wrap in azimuth) shorter than this many pixels are
    /// dropped as noise, pixels (default 3, the floor of the authors' rule; 0 or 1 keeps every
    /// run; at most 4096).
    pub min_obstacle_run_px: u32,
    /// Obstacle runs along a row whose arc length (Σρ)·2π/A is below this are dropped too,
    /// metres (default 0: off — the authors drop runs under 0.3 m of arc at the run's last pixel
    /// as well, not adopted for the robot, measured: the local planner README, rule 5;
    /// simulation 0.3 with the pixel rule off, spomp's former rule, measured: see
    /// [`TerrainParams::simulation`]; finite, ≥ 0).
    pub min_obstacle_run_m: f64,
    /// D_max: cap of the distance transform, metres (default 2.0; finite, > 0).
    pub max_obstacle_distance_m: f64,
    /// Traversable where the distance to the nearest obstacle is at least this, metres
    /// (default 0.5, simulation 0.75; finite, in [0, `max_obstacle_distance_m`]).
    pub inflation_m: f64,
    /// Reachability: a jump in horizontal range between successive returns of a column larger
    /// than this ends the known ground (unknown beyond), metres (default 2.0, the authors'
    /// launch value; simulation 0.5; finite, > 0).
    pub reach_gap_m: f64,
    /// Reachability: every bin's safe range is at least this, metres — the blind zone around
    /// the robot is taken as safe, as the authors do (default 0.5, simulation 0: measured, see
    /// [`TerrainParams::simulation`]; finite, ≥ 0).
    pub min_reach_range_m: f64,
    /// Range cell of the polar clearance table a [`crate::SafeRegion`] builds for the
    /// controller, metres (default 0.1; finite, > 0).
    pub clearance_cell_m: f64,
}

/// Largest accepted [`TerrainParams::min_obstacle_run_px`] (four times the default panorama's width).
const MAX_OBSTACLE_RUN_PX: u32 = 4096;

impl Default for TerrainParams {
    fn default() -> Self {
        TerrainParams {
            hole_fill_max_m: 0.1,
            gradient_window_m: 0.5,
            gradient_window_max_fraction: 0.2,
            sensor_height_m: 0.4,
            range_noise_m: 0.05,
            slope_threshold: 0.3,
            min_obstacle_run_px: 3,
            min_obstacle_run_m: 0.0,
            max_obstacle_distance_m: 2.0,
            inflation_m: 0.5,
            reach_gap_m: 2.0,
            min_reach_range_m: 0.5,
            clearance_cell_m: 0.1,
        }
    }
}

impl TerrainParams {
    /// The paper's simulation values, slope threshold 0.25 and inflation 0.75 m, a 0.5 m
    /// reachability gap and no floor under a bin's safe range; the rest as
    /// [`TerrainParams::default`].
    ///
    /// No floor in simulation (measured): the simulated sensor sees the ground from 0.4 m out,
    /// so a bin whose bottom pixel is not traversable has an obstacle within the 0.75 m
    /// inflation right beside the robot, and the authors' 0.5 m floor declared that stretch
    /// safe (with no clearance samples in it, the controller's clearance there is the 2 m
    /// default). With the floor alone added to the former rules, the shipped team mission
    /// fell from 54 to 45 of 60 clusters (seeds 1–4) and reported "no progress for 30 s" 87
    /// times against once.
    ///
    /// The gap stays at 0.5 m in simulation (measured): with the authors' 2 m, 971 of the 1024
    /// columns of the simulator's parking-lot panorama end at a known obstacle (407 before the
    /// issue-20 rules, 438 with them and 0.5 m), the planner's graph updates turn those into
    /// untraversable edges, and the shipped team mission fell from 143 to 99 of 150 clusters
    /// (seeds 1–10).
    ///
    /// Short obstacle runs are measured in metres of arc in simulation, not in pixels
    /// (measured): with the authors' 3-pixel rule the simulator's panoramas keep the near,
    /// few-centimetre runs its rendered kerbs and bumpers leave, each inflated by 0.75 m, and
    /// the traversable area shrank by 2–10 %; the shipped team mission then visited 537
    /// clusters against 554 over seeds 1–40. See the local planner's README, rule 5.
    pub fn simulation() -> Self {
        TerrainParams {
            slope_threshold: 0.25,
            min_obstacle_run_px: 0,
            min_obstacle_run_m: 0.3,
            inflation_m: 0.75,
            reach_gap_m: 0.5,
            min_reach_range_m: 0.0,
            ..Self::default()
        }
    }

    /// Stage 4's noise filter for obstacle runs, from `min_obstacle_run_px` and
    /// `min_obstacle_run_m`.
    pub fn run_filter(&self) -> stages::RunFilter {
        stages::RunFilter { min_px: self.min_obstacle_run_px, min_arc_m: self.min_obstacle_run_m as f32 }
    }

    /// Checks every field's range (see each field's documentation).
    pub fn validate(&self) -> Result<(), ParamsError> {
        non_negative("hole_fill_max_m", self.hole_fill_max_m)?;
        positive("gradient_window_m", self.gradient_window_m)?;
        positive("gradient_window_max_fraction", self.gradient_window_max_fraction)?;
        if self.gradient_window_max_fraction > 1.0 {
            return Err(ParamsError::new("gradient_window_max_fraction", "must be <= 1"));
        }
        positive("sensor_height_m", self.sensor_height_m)?;
        non_negative("range_noise_m", self.range_noise_m)?;
        positive("slope_threshold", self.slope_threshold)?;
        if self.min_obstacle_run_px > MAX_OBSTACLE_RUN_PX {
            return Err(ParamsError::new("min_obstacle_run_px", "must be <= 4096"));
        }
        non_negative("min_obstacle_run_m", self.min_obstacle_run_m)?;
        positive("max_obstacle_distance_m", self.max_obstacle_distance_m)?;
        non_negative("inflation_m", self.inflation_m)?;
        if self.inflation_m > self.max_obstacle_distance_m {
            return Err(ParamsError::new("inflation_m", "must be <= max_obstacle_distance_m"));
        }
        positive("reach_gap_m", self.reach_gap_m)?;
        non_negative("min_reach_range_m", self.min_reach_range_m)?;
        positive("clearance_cell_m", self.clearance_cell_m)?;
        Ok(())
    }
}

/// The stages of terrain analysis, in order.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum TerrainStage {
    /// Sanitise ranges and fill small holes along rows.
    FillHoles,
    /// Projection to height z and horizontal range r (x, y on demand).
    Project,
    /// Gradient magnitude with metric windows.
    Gradients,
    /// Threshold and removal of short obstacle runs.
    Obstacles,
    /// Distance transform (Algorithm 1) and traversable mask.
    DistanceTransform,
    /// Reachability scan S(φ).
    Reachability,
}

impl TerrainStage {
    /// All stages in execution order.
    pub const ALL: [TerrainStage; 6] = [
        TerrainStage::FillHoles,
        TerrainStage::Project,
        TerrainStage::Gradients,
        TerrainStage::Obstacles,
        TerrainStage::DistanceTransform,
        TerrainStage::Reachability,
    ];

    /// A short name for logs and file names.
    pub fn name(self) -> &'static str {
        match self {
            TerrainStage::FillHoles => "fill_holes",
            TerrainStage::Project => "project",
            TerrainStage::Gradients => "gradients",
            TerrainStage::Obstacles => "obstacles",
            TerrainStage::DistanceTransform => "distance_transform",
            TerrainStage::Reachability => "reachability",
        }
    }
}

/// Everything terrain analysis computes for one panorama. Per-pixel buffers are row-major
/// `rows × cols` like the panorama; per-column buffers have `cols` entries.
#[derive(Clone, Debug, Default)]
pub struct TerrainOutput {
    geometry: Option<PanoramaGeometry>,
    ranges_m: Vec<f32>,
    col_cos: Vec<f32>,
    col_sin: Vec<f32>,
    z_m: Vec<f32>,
    r_m: Vec<f32>,
    gradient: Vec<f32>,
    obstacle: Vec<bool>,
    column_distance_m: Vec<f32>,
    distance_m: Vec<f32>,
    traversable: Vec<bool>,
    reach_range_m: Vec<f32>,
    reach_obstacle: Vec<bool>,
    reach_last_row: Vec<u32>,
}

impl TerrainOutput {
    fn new(geometry: PanoramaGeometry, tables: &Tables) -> Self {
        let n = geometry.len();
        let a = geometry.cols;
        TerrainOutput {
            geometry: Some(geometry),
            ranges_m: vec![0.0; n],
            col_cos: tables.col_cos.clone(),
            col_sin: tables.col_sin.clone(),
            z_m: vec![0.0; n],
            r_m: vec![0.0; n],
            gradient: vec![0.0; n],
            obstacle: vec![false; n],
            column_distance_m: vec![0.0; n],
            distance_m: vec![0.0; n],
            traversable: vec![false; n],
            reach_range_m: vec![0.0; a],
            reach_obstacle: vec![false; a],
            reach_last_row: vec![geometry.rows as u32; a],
        }
    }

    /// Panorama geometry.
    pub fn geometry(&self) -> PanoramaGeometry {
        self.geometry.unwrap_or(PanoramaGeometry { rows: 0, cols: 0, v_fov_rad: 0.0 })
    }
    /// Ranges after sanitising and hole filling, metres (0: no return).
    pub fn ranges_m(&self) -> &[f32] {
        &self.ranges_m
    }
    /// The point (x forward, y left, z up; sensor frame, metres) of pixel `index` (row-major),
    /// `None` without a return or out of range.
    pub fn point_m(&self, index: usize) -> Option<[f32; 3]> {
        let cols = self.col_cos.len();
        let (r, z) = (*self.r_m.get(index)?, *self.z_m.get(index)?);
        if cols == 0 || r.is_nan() {
            return None;
        }
        let c = index % cols;
        Some([r * self.col_cos[c], r * self.col_sin[c], z])
    }
    /// z per pixel relative to the sensor (up), metres; NaN without a return.
    pub fn z_m(&self) -> &[f32] {
        &self.z_m
    }
    /// Horizontal range r = ρ·cos θ per pixel, metres; NaN without a return.
    pub fn r_m(&self) -> &[f32] {
        &self.r_m
    }
    /// Gradient magnitude |∇| per pixel (rise over run).
    pub fn gradient(&self) -> &[f32] {
        &self.gradient
    }
    /// Obstacle mask after removing short runs.
    pub fn obstacle(&self) -> &[bool] {
        &self.obstacle
    }
    /// D_a of Algorithm 1: distance from the column pass alone, metres.
    pub fn column_distance_m(&self) -> &[f32] {
        &self.column_distance_m
    }
    /// D of Algorithm 1: approximate distance to the nearest obstacle, in [0, D_max], metres.
    pub fn distance_m(&self) -> &[f32] {
        &self.distance_m
    }
    /// Traversable mask: a return at least the inflation distance from any obstacle.
    pub fn traversable(&self) -> &[bool] {
        &self.traversable
    }
    /// S(φ) range per column: known-safe horizontal distance, metres.
    pub fn reach_range_m(&self) -> &[f32] {
        &self.reach_range_m
    }
    /// S(φ) flag per column: a known obstacle ends the safe stretch.
    pub fn reach_obstacle(&self) -> &[bool] {
        &self.reach_obstacle
    }
    /// Last (highest) safe row of each column's walk; `rows` when the column has none.
    pub fn reach_last_row(&self) -> &[u32] {
        &self.reach_last_row
    }

    /// The reachability scan as the team shares it.
    pub fn to_scan(&self, robot: RobotId, stamp: Time, pose: Pose2) -> ReachabilityScan {
        ReachabilityScan {
            robot,
            stamp,
            pose,
            range_m: self.reach_range_m.clone(),
            obstacle: self.reach_obstacle.clone(),
        }
    }
}

/// Instruction sets the terrain stages are compiled for; [`TerrainAnalyzer::new`] picks the
/// widest the processor has. The results are bit for bit the same with each.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum InstructionSet {
    /// The build's baseline (SSE2 on x86-64): every processor the binary runs on.
    Baseline,
    /// x86-64-v3: AVX2, FMA and their companions.
    Avx2,
    /// x86-64-v4: AVX-512 (F, BW, CD, DQ, VL).
    Avx512,
}

impl InstructionSet {
    /// Every instruction set, narrowest first.
    pub const ALL: [InstructionSet; 3] = [InstructionSet::Baseline, InstructionSet::Avx2, InstructionSet::Avx512];

    /// The dispatcher for this set, if this processor has it.
    fn arch(self) -> Option<pulp::Arch> {
        match self {
            InstructionSet::Baseline => Some(pulp::Arch::Scalar),
            #[cfg(any(target_arch = "x86", target_arch = "x86_64"))]
            InstructionSet::Avx2 => pulp::x86::V3::try_new().map(pulp::Arch::V3),
            #[cfg(any(target_arch = "x86", target_arch = "x86_64"))]
            InstructionSet::Avx512 => pulp::x86::V4::try_new().map(pulp::Arch::V4),
            #[cfg(not(any(target_arch = "x86", target_arch = "x86_64")))]
            InstructionSet::Avx2 | InstructionSet::Avx512 => None,
        }
    }
}

/// Runs terrain analysis on panoramas of one geometry, reusing its tables and buffers: no
/// allocation per panorama.
#[derive(Clone, Debug)]
pub struct TerrainAnalyzer {
    geometry: PanoramaGeometry,
    params: TerrainParams,
    tables: Tables,
    gradient_scratch: GradientScratch,
    distance_scratch: DistanceScratch,
    reach_scratch: ReachScratch,
    /// One sanitised row for hole filling.
    fill_scratch: Vec<f32>,
    output: TerrainOutput,
    /// The widest instruction set of this processor (AVX-512, AVX2 with FMA, or the build's
    /// baseline, SSE2 on x86-64), detected once: the stages run compiled for it.
    simd: pulp::Arch,
}

impl TerrainAnalyzer {
    /// An analyzer for panoramas of `geometry`.
    pub fn new(geometry: PanoramaGeometry, params: TerrainParams) -> Result<Self, TerrainError> {
        params.validate()?;
        let fov_ok =
            geometry.v_fov_rad.is_finite() && geometry.v_fov_rad > 0.0 && geometry.v_fov_rad <= std::f64::consts::PI;
        if geometry.rows < 2 || geometry.cols < 3 || !fov_ok {
            return Err(TerrainError::BadGeometry(geometry));
        }
        // At most 4 Mi pixels (16 × the default 256 × 1024): the analyzer holds ~14 buffers of them.
        if geometry.rows.checked_mul(geometry.cols).is_none_or(|n| n > (1 << 22)) {
            return Err(TerrainError::BadGeometry(geometry));
        }
        let tables = Tables::new(
            geometry.rows,
            geometry.cols,
            |row| geometry.elevation_of_row(row),
            params.sensor_height_m,
            params.gradient_window_m,
            params.range_noise_m,
        );
        let output = TerrainOutput::new(geometry, &tables);
        Ok(TerrainAnalyzer {
            geometry,
            params,
            tables,
            gradient_scratch: GradientScratch::default(),
            distance_scratch: DistanceScratch::default(),
            reach_scratch: ReachScratch::default(),
            fill_scratch: Vec::with_capacity(geometry.cols),
            output,
            simd: pulp::Arch::new(),
        })
    }

    /// Runs the stages compiled for `set` from now on; false (and no change) if this processor
    /// lacks it. For comparing the code paths; the default is the widest available.
    pub fn select_instruction_set(&mut self, set: InstructionSet) -> bool {
        match set.arch() {
            Some(simd) => {
                self.simd = simd;
                true
            }
            None => false,
        }
    }

    /// The geometry this analyzer accepts.
    pub fn geometry(&self) -> PanoramaGeometry {
        self.geometry
    }

    /// The parameters in use.
    pub fn params(&self) -> &TerrainParams {
        &self.params
    }

    /// The precomputed tables (trigonometry, w_e, noise per row).
    pub fn tables(&self) -> &Tables {
        &self.tables
    }

    /// The result of the last analysis (all zeros before the first).
    pub fn output(&self) -> &TerrainOutput {
        &self.output
    }

    /// Runs all stages on `depth`.
    ///
    /// Stages 1–5 run fused, row by row from the top (each stage of a row only needs that row
    /// and rows above it), so that a row's data stays in cache; the result is identical to
    /// running the stages one after the other ([`Self::analyze_observed`]).
    pub fn analyze(&mut self, depth: &DepthPanorama) -> Result<&TerrainOutput, TerrainError> {
        self.check(depth)?;
        self.simd.dispatch(Fused { analyzer: self, depth });
        Ok(&self.output)
    }

    /// Stages 1–6 with 1–5 fused ([`Self::analyze`] without the checks).
    #[inline(always)]
    fn run_all_fused<S: pulp::Simd>(&mut self, depth: &DepthPanorama, simd: S) {
        self.run_fused(depth, simd);
        self.run_stage_inline(TerrainStage::Reachability, depth, simd);
    }

    /// Stages 1–5, fused row by row, compiled for the instruction set of `simd` (with AVX2 or
    /// AVX-512, `wide_registers`, some stages pick other loops; Algorithm 1's row passes run on
    /// blocks of one row per lane of its native vector).
    #[inline(always)]
    fn run_fused<S: pulp::Simd>(&mut self, depth: &DepthPanorama, simd: S) {
        let wide_registers = !S::IS_SCALAR;
        let TerrainAnalyzer {
            geometry,
            params: p,
            tables,
            gradient_scratch,
            distance_scratch,
            fill_scratch,
            output: out,
            ..
        } = self;
        let (rows, cols) = (geometry.rows, geometry.cols);
        let window = GradientWindow {
            window_m: p.gradient_window_m as f32,
            max_window_px: (p.gradient_window_max_fraction * cols as f64) as f32,
        };
        let step = std::f32::consts::TAU / cols as f32;
        let d_max = p.max_obstacle_distance_m as f32;
        let (nearest, block) = distance_scratch.reset(cols);
        let block_rows = stages::native_block_rows::<S>();
        let block_width = block_rows * cols;
        for row in 0..rows {
            let span = row * cols..(row + 1) * cols;
            let (sin_e, cos_e) = (tables.row_sin[row], tables.row_cos[row]);
            stages::fill_holes_with(
                &depth.range_m[span.clone()],
                &mut out.ranges_m[span.clone()],
                cols,
                p.hole_fill_max_m as f32,
                fill_scratch,
                wide_registers,
            );
            let rho = &out.ranges_m[span.clone()];
            stages::project_row(rho, sin_e, cos_e, &mut out.z_m[span.clone()], &mut out.r_m[span.clone()]);
            let gradient = &mut out.gradient[span.clone()];
            stages::gradient_row(row, &out.z_m, &out.r_m, tables, window, gradient_scratch, gradient, simd);
            let obstacle = &mut out.obstacle[span.clone()];
            stages::obstacles(gradient, rho, cols, p.slope_threshold as f32, p.run_filter(), obstacle);
            let d_a = &mut out.column_distance_m[span.clone()];
            stages::column_pass_row(rho, obstacle, nearest, d_max, d_a, wide_registers);
            // Algorithm 1's row passes run on blocks of rows, one per SIMD lane, as soon as a block
            // has its column pass; rows past the last full block run alone.
            if (row + 1) % block_rows == 0 {
                let block_span = (row + 1) * cols - block_width..(row + 1) * cols;
                let (rho, d_a) = (&out.ranges_m[block_span.clone()], &out.column_distance_m[block_span.clone()]);
                let distance = &mut out.distance_m[block_span.clone()];
                stages::row_passes_block_native(simd, rho, d_a, distance, cols, step, d_max, block);
                stages::traversable(rho, distance, p.inflation_m as f32, &mut out.traversable[block_span]);
            } else if row >= rows / block_rows * block_rows {
                let distance = &mut out.distance_m[span.clone()];
                stages::row_passes(rho, d_a, distance, step, d_max);
                stages::traversable(rho, distance, p.inflation_m as f32, &mut out.traversable[span]);
            }
        }
    }

    /// Runs the stages one after the other over the whole panorama, calling `after_stage` as
    /// each stage completes (a caller can read its clock there to time the stages, or inspect
    /// [`Self::output`]). Same result as [`Self::analyze`], which is faster.
    pub fn analyze_observed(
        &mut self,
        depth: &DepthPanorama,
        mut after_stage: impl FnMut(TerrainStage),
    ) -> Result<&TerrainOutput, TerrainError> {
        self.check(depth)?;
        for stage in TerrainStage::ALL {
            self.run_stage(stage, depth);
            after_stage(stage);
        }
        Ok(&self.output)
    }

    /// Runs one stage on `depth` (only [`TerrainStage::FillHoles`] reads it; later stages read
    /// the output of the earlier ones, so run them in order).
    pub fn run_single_stage(
        &mut self,
        stage: TerrainStage,
        depth: &DepthPanorama,
    ) -> Result<&TerrainOutput, TerrainError> {
        self.check(depth)?;
        self.run_stage(stage, depth);
        Ok(&self.output)
    }

    fn check(&self, depth: &DepthPanorama) -> Result<(), TerrainError> {
        if depth.geometry != self.geometry {
            return Err(TerrainError::GeometryMismatch { expected: self.geometry, found: depth.geometry });
        }
        if depth.range_m.len() != self.geometry.len() {
            return Err(TerrainError::BufferLength { expected: self.geometry.len(), found: depth.range_m.len() });
        }
        Ok(())
    }

    /// Runs one stage compiled for the processor's widest instruction set.
    fn run_stage(&mut self, stage: TerrainStage, depth: &DepthPanorama) {
        self.simd.dispatch(SingleStage { analyzer: self, stage, depth });
    }

    /// [`Self::run_stage`] inside the dispatched function (`simd` as for [`Self::run_fused`]).
    #[inline(always)]
    fn run_stage_inline<S: pulp::Simd>(&mut self, stage: TerrainStage, depth: &DepthPanorama, simd: S) {
        let wide_registers = !S::IS_SCALAR;
        let cols = self.geometry.cols;
        let p = &self.params;
        let out = &mut self.output;
        match stage {
            TerrainStage::FillHoles => stages::fill_holes_with(
                &depth.range_m,
                &mut out.ranges_m,
                cols,
                p.hole_fill_max_m as f32,
                &mut self.fill_scratch,
                wide_registers,
            ),
            TerrainStage::Project => stages::project(&out.ranges_m, &self.tables, &mut out.z_m, &mut out.r_m),
            TerrainStage::Gradients => stages::gradients_with(
                &out.z_m,
                &out.r_m,
                &self.tables,
                GradientWindow {
                    window_m: p.gradient_window_m as f32,
                    max_window_px: (p.gradient_window_max_fraction * cols as f64) as f32,
                },
                &mut self.gradient_scratch,
                &mut out.gradient,
                simd,
            ),
            TerrainStage::Obstacles => stages::obstacles(
                &out.gradient,
                &out.ranges_m,
                cols,
                p.slope_threshold as f32,
                p.run_filter(),
                &mut out.obstacle,
            ),
            TerrainStage::DistanceTransform => {
                stages::distance_transform_with(
                    &out.ranges_m,
                    &out.obstacle,
                    cols,
                    p.max_obstacle_distance_m as f32,
                    &mut self.distance_scratch,
                    &mut out.column_distance_m,
                    &mut out.distance_m,
                    simd,
                );
                stages::traversable(&out.ranges_m, &out.distance_m, p.inflation_m as f32, &mut out.traversable);
            }
            TerrainStage::Reachability => stages::reachability(
                &out.r_m,
                &out.ranges_m,
                &out.traversable,
                cols,
                p.reach_gap_m as f32,
                p.min_reach_range_m as f32,
                &mut self.reach_scratch,
                &mut out.reach_range_m,
                &mut out.reach_obstacle,
                &mut out.reach_last_row,
            ),
        }
    }
}

/// [`TerrainAnalyzer::analyze`]'s work as a [`pulp::WithSimd`] operation: `pulp` runs it inside a
/// function compiled for the detected instruction set, and the stages, all `#[inline(always)]`,
/// are compiled into it (the `wide` vectors then use VEX or EVEX encodings, and the compiler may
/// use the wider registers for the loops it vectorises itself).
struct Fused<'a> {
    analyzer: &'a mut TerrainAnalyzer,
    depth: &'a DepthPanorama,
}

impl pulp::WithSimd for Fused<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, simd: S) {
        self.analyzer.run_all_fused(self.depth, simd);
    }
}

/// One stage of [`TerrainAnalyzer::analyze_observed`] as a [`pulp::WithSimd`] operation (see
/// [`Fused`]).
struct SingleStage<'a> {
    analyzer: &'a mut TerrainAnalyzer,
    stage: TerrainStage,
    depth: &'a DepthPanorama,
}

impl pulp::WithSimd for SingleStage<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, simd: S) {
        self.analyzer.run_stage_inline(self.stage, self.depth, simd);
    }
}
