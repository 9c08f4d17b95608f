//! Edge costs: −log P summed along an edge from the learned traversability (MLP trained online
//! on scan labels) or, with learning off, the class-rank cost; experience on top.

#[allow(clippy::wildcard_imports)]
use super::*;

impl GlobalPlanner {
    /// Cost of the cells sampled along a segment from the map alone.
    pub(super) fn base_cost(&mut self, samples: &[u32]) -> f64 {
        let Some(map) = &self.map else { return 0.0 };
        if !self.params.learning.enabled {
            return self.class_rank_cost(map, samples);
        }
        let channels = self.features.channels();
        let mut feats = std::mem::take(&mut self.segment_features);
        feats.clear();
        for &s in samples {
            feats.resize(feats.len() + channels, 0.0);
            let start = feats.len() - channels;
            if !self.features.fill(map, s as usize, &mut feats[start..]) {
                feats.truncate(start);
            }
        }
        let cost = self.learned_cost(&feats, samples.len());
        self.segment_features = feats;
        cost
    }

    /// Σ −log T over `n_samples` samples, of which the rows of `features` are the mapped ones:
    /// the mean over mapped samples × `n_samples` (paper); −log 0.5 per sample when nothing is
    /// mapped or the model is untrained.
    pub(super) fn learned_cost(&mut self, features: &[f32], n_samples: usize) -> f64 {
        let n = n_samples.max(1) as f64;
        let channels = self.features.channels();
        let known = features.len() / channels.max(1);
        if !self.model.is_trained() || known == 0 {
            return n * std::f64::consts::LN_2;
        }
        let floor = self.params.learning.probability_floor.clamp(1e-12, 0.5);
        let mut sum = 0.0;
        for row in features.chunks_exact(channels) {
            let t = self.model.probability(row) as f64;
            let t = if t.is_finite() { t.clamp(floor, 1.0) } else { floor };
            sum -= t.ln();
        }
        sum / known as f64 * n
    }

    /// [`Self::learned_cost`] over packed features ([`Features::pack`]): the same sum over the
    /// same rows. Compiled for the processor's widest vectors (run for every sample of every
    /// edge after each training round): the network's padded hidden layer is one AVX-512
    /// register where the baseline needs four; the same operations, so the same bits.
    pub(super) fn learned_cost_packed(&mut self, packed: &[u8], n_samples: usize) -> f64 {
        let n = n_samples.max(1) as f64;
        let record = self.features.packed_len();
        let known = packed.len() / record.max(1);
        if !self.model.is_trained() || known == 0 {
            return n * std::f64::consts::LN_2;
        }
        let floor = self.params.learning.probability_floor.clamp(1e-12, 0.5);
        let mut row = std::mem::take(&mut self.feature_scratch);
        row.resize(self.features.channels(), 0.0);
        let sum = self.simd.dispatch(PackedCost {
            model: &mut self.model,
            features: &self.features,
            packed,
            record,
            row: &mut row,
            floor,
        });
        self.feature_scratch = row;
        sum / known as f64 * n
    }

    /// The learning-off ablation: W = 100^T_cls − 1 + D, T_cls the rank of the hardest class on
    /// the edge, D the least distance from a sample to the next harder class present.
    pub(super) fn class_rank_cost(&self, map: &AerialMap, samples: &[u32]) -> f64 {
        let mut hardest: Option<u8> = None;
        for &s in samples {
            let c = map.class.get(s as usize).copied().unwrap_or(UNKNOWN_CLASS);
            if c != UNKNOWN_CLASS {
                let r = self.rank_of_class[c as usize];
                hardest = Some(hardest.map_or(r, |h: u8| h.max(r)));
            }
        }
        let t_cls = hardest.unwrap_or(self.params.graph.max_class_rank);
        let next_rank = self.classes.classes.iter().map(|c| c.rank).filter(|&r| r > t_cls).min();
        let mut d = self.params.learning.class_distance_cap_m;
        if let Some(next) = next_rank {
            for &s in samples {
                for c in self.classes.classes.iter().filter(|c| c.rank == next) {
                    d = d.min(self.features.class_distance_m(s as usize, c.index) as f64);
                }
            }
        }
        100f64.powi(t_cls as i32) - 1.0 + d
    }

    pub(super) fn experienced_cost(&self, base: f64, n_samples: usize, exp: &EdgeExperience) -> f64 {
        let p = &self.params.experience;
        let n = n_samples.max(1) as f64;
        let nll = |prob: f64| -prob.clamp(1e-12, 1.0).ln();
        match exp.state {
            EdgeState::Unknown => base,
            EdgeState::Trav => base.min(n * nll(p.trav_sample_probability)),
            EdgeState::NotTrav => base + n * nll(p.not_trav_sample_probability),
        }
    }

    /// Recomputes every edge's cost; `map_changed` also refreshes the cached sample features.
    pub(super) fn refresh_all_costs(&mut self, map_changed: bool) {
        let mut ids = std::mem::take(&mut self.edge_ids);
        ids.clear();
        ids.extend(self.graph.edge_indices());
        let learning = self.params.learning.enabled;
        for &e in &ids {
            let Some(d) = self.graph.edge_weight_mut(e) else { continue };
            let mut samples = std::mem::take(&mut d.samples);
            let mut feats = std::mem::take(&mut d.features);
            let base = if !learning {
                self.base_cost(&samples)
            } else {
                if map_changed || (feats.is_empty() && !samples.is_empty()) {
                    feats.clear();
                    if let Some(map) = &self.map {
                        for &s in &samples {
                            self.features.pack(map, s as usize, &mut feats);
                        }
                    }
                }
                self.learned_cost_packed(&feats, samples.len())
            };
            if let Some(d) = self.graph.edge_weight_mut(e) {
                std::mem::swap(&mut d.samples, &mut samples);
                std::mem::swap(&mut d.features, &mut feats);
                d.base_cost = base;
            }
            self.refresh_edge_cost(e);
        }
        self.edge_ids = ids;
        self.refresh_heuristic_rate();
    }

    pub(super) fn refresh_edge_cost(&mut self, e: EdgeIndex<u32>) {
        let Some(d) = self.graph.edge_weight(e) else {
            return;
        };
        let mut cost = self.experienced_cost(d.base_cost, d.samples.len(), &d.experience);
        if d.up_curb
            && self.params.graph.curbs_last_resort
            && self.params.experience.graph_updates
            && d.experience.state != EdgeState::Trav
        {
            cost += LAST_RESORT_COST;
        }
        if let Some(d) = self.graph.edge_weight_mut(e) {
            d.cost = cost;
        }
    }

    /// Least cost per metre over all edges: A*'s heuristic rate, admissible by construction.
    pub(super) fn refresh_heuristic_rate(&mut self) {
        let mut rate = f64::INFINITY;
        for d in self.graph.edge_weights() {
            if d.length_m > 1e-9 {
                rate = rate.min(d.cost / d.length_m);
            } else {
                rate = rate.min(0.0);
            }
        }
        self.min_cost_per_m = if rate.is_finite() { rate.max(0.0) } else { 0.0 };
    }

    /// Whether a training round is due at `now` (learning on, and the training period passed
    /// since the last round): a caller can then hand the planner to work off its tick thread.
    pub fn training_due(&self, now: Time) -> bool {
        self.params.learning.enabled
            && self.last_train.is_none_or(|last| now.secs_since(last) >= self.params.learning.train_period_s)
    }

    /// Runs a training round if learning is on, at least the training period passed since the
    /// last round and enough cells are labelled; then refreshes every edge's cost.
    pub fn train(&mut self, now: Time, rng: &mut impl Rng) -> TrainOutcome {
        if !self.params.learning.enabled {
            return TrainOutcome::Disabled;
        }
        if !self.training_due(now) {
            return TrainOutcome::TooSoon;
        }
        let l = &self.params.learning;
        let Some(map) = &self.map else {
            return TrainOutcome::NotEnoughLabels { labels: 0 };
        };
        // The labelled cells the map has features for, in label order. With more of them than
        // a round draws (8192 draws, where the team's scans label up to hundreds of thousands
        // of cells), features are built for the drawn rows only.
        self.train_cells.clear();
        self.train_cells.extend(
            self.votes
                .labels(l.votes_to_label)
                .filter(|&(cell, _)| map.class.get(cell).is_some_and(|&c| c != UNKNOWN_CLASS)),
        );
        let labels = self.train_cells.len();
        if labels < l.min_labels.max(1) {
            self.release_training_set();
            return TrainOutcome::NotEnoughLabels { labels };
        }
        let settings = TrainSettings {
            l2: l.l2_regularization as f32,
            step_size: l.step_size as f32,
            decay: l.rmsprop_decay as f32,
            epsilon: l.rmsprop_epsilon as f32,
            batch_size: l.batch_size.max(1),
            samples: l.samples_per_round,
        };
        let (features, cells) = (&self.features, &self.train_cells);
        let loss = if labels <= settings.samples {
            // Fewer rows than draws: each row's features built once, in label order (a row
            // drawn again is read back, not rebuilt from scattered map cells).
            let channels = features.channels();
            let mut rows = vec![0.0f32; labels * channels];
            for (x, &(cell, _)) in rows.chunks_exact_mut(channels).zip(cells) {
                features.fill(map, cell, x);
            }
            let row = |r: usize, x: &mut [f32]| {
                x.copy_from_slice(&rows[r * channels..(r + 1) * channels]);
                cells[r].1
            };
            self.model.train_rows(labels, row, settings, rng)
        } else {
            let row = |r: usize, x: &mut [f32]| {
                let (cell, label) = cells[r];
                features.fill(map, cell, x);
                label
            };
            self.model.train_rows(labels, row, settings, rng)
        };
        self.release_training_set();
        self.last_train = Some(now);
        self.training_rounds += 1;
        self.refresh_all_costs(false);
        TrainOutcome::Trained { labels, loss }
    }

    /// Gives back the training set: 16 bytes per labelled cell, and the labels grow with every
    /// scan the team shares (tens of MB per robot over a long run of a large team), while a
    /// round needs it only for its duration.
    fn release_training_set(&mut self) {
        self.train_cells = Vec::new();
    }

    /// Learned probability that the cell under `p` is traversable (0.5 before training); `None`
    /// off the map or on unmapped cells.
    pub fn traversability_at(&mut self, p: Point2) -> Option<f64> {
        if !(p.x.is_finite() && p.y.is_finite()) {
            return None;
        }
        let map = self.map.as_ref()?;
        let cell = map.spec.cell_at(p)?;
        let i = map.spec.index(cell);
        if !self.features.fill(map, i, &mut self.feature_scratch) {
            return None;
        }
        Some(self.model.probability(&self.feature_scratch) as f64)
    }
}

/// Σ −log T over the packed rows of one edge, as a [`pulp::WithSimd`] operation: `pulp` runs it
/// inside a function compiled for the detected instruction set, with the unpacking and the
/// network (all `#[inline(always)]`) compiled into it.
struct PackedCost<'a> {
    model: &'a mut Mlp,
    features: &'a Features,
    packed: &'a [u8],
    record: usize,
    row: &'a mut [f32],
    floor: f64,
}

impl pulp::WithSimd for PackedCost<'_> {
    type Output = f64;

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) -> f64 {
        let mut sum = 0.0;
        for cell in self.packed.chunks_exact(self.record) {
            self.features.unpack(cell, self.row);
            let t = self.model.probability(self.row) as f64;
            let t = if t.is_finite() { t.clamp(self.floor, 1.0) } else { self.floor };
            sum -= t.ln();
        }
        sum
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use spomp_core::GridSpec;
    use spomp_raster::SquaredEdt;

    /// The processor's instruction sets a dispatched operation can run on here, baseline first.
    fn arches() -> Vec<pulp::Arch> {
        let mut arches = vec![pulp::Arch::Scalar];
        #[cfg(any(target_arch = "x86", target_arch = "x86_64"))]
        {
            arches.extend(pulp::x86::V3::try_new().map(pulp::Arch::V3));
            arches.extend(pulp::x86::V4::try_new().map(pulp::Arch::V4));
        }
        arches
    }

    /// An edge's learned cost is the same bits whichever instruction set the dispatch picks: the
    /// simulator's results must not depend on the machine.
    #[test]
    fn learned_edge_cost_has_the_same_bits_on_every_instruction_set() {
        let table = ClassTable::default_table();
        let spec = GridSpec::new(Point2::new(0.0, 0.0), 0.5, 60, 40);
        let mut map = AerialMap::unknown(spec);
        for i in 0..map.class.len() {
            map.class[i] = [0u8, 1, 2, 3, 6][(i * 7 + i / 60) % 5];
            map.rgb[i] = [(i % 251) as u8, (i * 3 % 241) as u8, (i * 7 % 239) as u8];
            map.elevation[i] = (i % 13) as f32 * 0.1;
        }
        let mut features = Features::new(&table);
        features.rebuild(&map, &mut SquaredEdt::default(), 5.0, ClassChange::All);
        let channels = features.channels();
        let (mut xs, mut ys, mut packed) = (Vec::new(), Vec::new(), Vec::new());
        let mut x = vec![0.0f32; channels];
        for i in (0..map.class.len()).step_by(3) {
            assert!(features.fill(&map, i, &mut x));
            xs.extend_from_slice(&x);
            ys.push(matches!(map.class[i], 0 | 6));
            features.pack(&map, i, &mut packed);
        }
        let mut model = Mlp::new(channels, 10);
        let settings =
            TrainSettings { l2: 0.01, step_size: 0.01, decay: 0.99, epsilon: 1e-8, batch_size: 32, samples: 2048 };
        model.train(&xs, &ys, settings, &mut ChaCha8Rng::seed_from_u64(3));
        let record = features.packed_len();
        let costs: Vec<f64> = arches()
            .into_iter()
            .map(|arch| {
                let mut row = vec![0.0f32; channels];
                let op = PackedCost {
                    model: &mut model,
                    features: &features,
                    packed: &packed,
                    record,
                    row: &mut row,
                    floor: 1e-3,
                };
                arch.dispatch(op)
            })
            .collect();
        assert!(costs[0].is_finite() && costs[0] > 0.0, "{costs:?}");
        assert!(costs.iter().all(|c| c.to_bits() == costs[0].to_bits()), "{costs:?}");
    }
}
