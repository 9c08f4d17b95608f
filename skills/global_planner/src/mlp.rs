//! The traversability MLP: one hidden layer of sigmoid units, a two-class softmax output,
//! cross-entropy loss with L2 regularisation on the weights, trained with RMSProp on mini-batches
//! (the paper's mlpack configuration, written out).

use rand::Rng;

/// Optimiser settings of one training round.
#[derive(Clone, Copy, Debug)]
pub(crate) struct TrainSettings {
    pub l2: f32,
    pub step_size: f32,
    pub decay: f32,
    pub epsilon: f32,
    pub batch_size: usize,
    pub samples: usize,
}

/// Hidden layers up to this wide run the first layer on fixed-width rows
/// ([`Mlp::forward_lanes`]).
const LANES: usize = 16;

/// Parameters (and their RMSProp accumulators) laid out flat:
/// `w1[inputs][hidden]`, `b1[hidden]`, `w2[2][hidden]`, `b2[2]`.
#[derive(Clone, Debug)]
pub(crate) struct Mlp {
    inputs: usize,
    hidden: usize,
    params: Vec<f32>,
    grad: Vec<f32>,
    mean_sq: Vec<f32>,
    hidden_act: Vec<f32>,
    back: Vec<f32>,
    trained: bool,
    /// `w1`'s rows padded with zeros to [`LANES`] hidden units (a hidden layer at most that
    /// wide): the per-input loop of the first layer is then a few whole vector operations,
    /// where a row of 10 was two vectors and a scalar tail. Rebuilt from `params` when stale.
    lanes_w1: Vec<[f32; LANES]>,
    /// `b1` padded the same way.
    lanes_b1: [f32; LANES],
    /// Whether `lanes_w1` and `lanes_b1` match `params`.
    lanes_fresh: bool,
}

impl Mlp {
    /// An untrained network; [`Mlp::probability`] returns 0.5 until the first round.
    pub fn new(inputs: usize, hidden: usize) -> Self {
        let hidden = hidden.max(1);
        let len = hidden * inputs + hidden + 2 * hidden + 2;
        Mlp {
            inputs,
            hidden,
            params: vec![0.0; len],
            grad: vec![0.0; len],
            mean_sq: vec![0.0; len],
            hidden_act: vec![0.0; hidden],
            back: vec![0.0; hidden],
            trained: false,
            lanes_w1: Vec::new(),
            lanes_b1: [0.0; LANES],
            lanes_fresh: false,
        }
    }

    /// Whether at least one training round ran.
    pub fn is_trained(&self) -> bool {
        self.trained
    }

    fn offsets(&self) -> (usize, usize, usize) {
        let b1 = self.hidden * self.inputs;
        let w2 = b1 + self.hidden;
        let b2 = w2 + 2 * self.hidden;
        (b1, w2, b2)
    }

    fn initialise(&mut self, rng: &mut impl Rng) {
        // Glorot-uniform weights, zero biases.
        let (b1, w2, b2) = self.offsets();
        let lim1 = (6.0 / (self.inputs + self.hidden) as f32).sqrt();
        let lim2 = (6.0 / (self.hidden + 2) as f32).sqrt();
        for p in &mut self.params[..b1] {
            *p = rng.random_range(-lim1..lim1);
        }
        self.params[b1..w2].fill(0.0);
        for p in &mut self.params[w2..b2] {
            *p = rng.random_range(-lim2..lim2);
        }
        self.params[b2..].fill(0.0);
        self.mean_sq.fill(0.0);
        self.lanes_fresh = false;
    }

    /// Copies the first layer out of `params` into the padded rows (hidden layers at most
    /// [`LANES`] wide).
    fn refresh_lanes(&mut self) {
        let nh = self.hidden;
        if nh > LANES {
            return;
        }
        let (b1, w2, _) = self.offsets();
        self.lanes_w1.clear();
        self.lanes_w1.extend(self.params[..b1].chunks_exact(nh).map(|row| {
            let mut lane = [0.0; LANES];
            lane[..nh].copy_from_slice(row);
            lane
        }));
        self.lanes_b1 = [0.0; LANES];
        self.lanes_b1[..nh].copy_from_slice(&self.params[b1..w2]);
        self.lanes_fresh = true;
    }

    /// [`Mlp::forward`] with the current parameters: the padded first layer when the hidden
    /// layer fits [`LANES`], the same sums in the same order, so the same bits.
    #[inline(always)]
    fn logit(&mut self, x: &[f32]) -> f32 {
        if self.hidden > LANES {
            return Self::forward(&self.params, self.inputs, x, &mut self.hidden_act);
        }
        if !self.lanes_fresh {
            self.refresh_lanes();
        }
        let (_, w2, b2) = self.offsets();
        Self::forward_lanes(&self.lanes_w1, &self.lanes_b1, &self.params[w2..], b2 - w2, x, &mut self.hidden_act)
    }

    /// [`Mlp::forward`] over padded first-layer rows `w1` and biases `b1`; `out` is the
    /// parameters from `w2` on (`w2[2][hidden]` then `b2[2]`, `b2` at `b2_at`). Every hidden
    /// unit's pre-activation is its bias plus the inputs' products added in input order, as
    /// in [`Mlp::forward`]; the padding lanes are computed and never read.
    #[inline(always)]
    fn forward_lanes(
        w1: &[[f32; LANES]],
        b1: &[f32; LANES],
        out: &[f32],
        b2_at: usize,
        x: &[f32],
        hidden: &mut [f32],
    ) -> f32 {
        let nh = hidden.len();
        let mut acc = *b1;
        for (row, &xi) in w1.iter().zip(x) {
            for (a, w) in acc.iter_mut().zip(row) {
                *a += w * xi;
            }
        }
        // All lanes' sigmoids at once (whole vector operations; the padding lanes are unread):
        // ten calls to libm's `expf` per cell were a third of the network's time.
        for a in &mut acc {
            *a = sigmoid(*a);
        }
        let (w_not, w_trav) = out[..b2_at].split_at(nh);
        let mut z = out[b2_at + 1] - out[b2_at];
        for (((h, a), wn), wt) in hidden.iter_mut().zip(&acc).zip(w_not).zip(w_trav) {
            *h = *a;
            z += (wt - wn) * *h;
        }
        z
    }

    /// Logit difference z_trav − z_not (the softmax of two logits is the sigmoid of this); the
    /// hidden activations are left in `hidden`. `w1` is stored input-major so the inner loop
    /// runs over the hidden units and vectorises.
    fn forward(params: &[f32], inputs: usize, x: &[f32], hidden: &mut [f32]) -> f32 {
        let nh = hidden.len();
        let b1 = nh * inputs;
        let w2 = b1 + nh;
        let b2 = w2 + 2 * nh;
        hidden.copy_from_slice(&params[b1..w2]);
        for (row, &xi) in params[..b1].chunks_exact(nh).zip(x) {
            for (h, w) in hidden.iter_mut().zip(row) {
                *h += w * xi;
            }
        }
        let (w_not, w_trav) = params[w2..b2].split_at(nh);
        let mut z = params[b2 + 1] - params[b2];
        for ((h, wn), wt) in hidden.iter_mut().zip(w_not).zip(w_trav) {
            *h = sigmoid(*h);
            z += (wt - wn) * *h;
        }
        z
    }

    /// P(traversable | x), 0.5 before training.
    #[inline(always)]
    pub fn probability(&mut self, x: &[f32]) -> f32 {
        if !self.trained || x.len() < self.inputs {
            return 0.5;
        }
        sigmoid(self.logit(x))
    }

    /// [`Mlp::train_rows`] over rows held in `features` (`inputs` wide) with `labels`.
    #[cfg(test)]
    pub fn train(&mut self, features: &[f32], labels: &[bool], settings: TrainSettings, rng: &mut impl Rng) -> f32 {
        let inputs = self.inputs;
        let rows = labels.len().min(features.len() / inputs.max(1));
        let row = |r: usize, x: &mut [f32]| {
            x.copy_from_slice(&features[r * inputs..(r + 1) * inputs]);
            labels[r]
        };
        self.train_rows(rows, row, settings, rng)
    }

    /// One training round: `settings.samples` rows drawn from `rows` (labels true =
    /// traversable), in mini-batches. `row(r, x)` fills `x` (`inputs` wide) with row r's
    /// features and returns its label. Returns the mean cross-entropy of the last epoch's worth
    /// of batches. A round draws
    /// `settings.samples` rows, often far fewer than the rows there are, so a caller whose rows
    /// take work to build builds only the drawn ones.
    pub fn train_rows(
        &mut self,
        rows: usize,
        row: impl FnMut(usize, &mut [f32]) -> bool,
        settings: TrainSettings,
        rng: &mut impl Rng,
    ) -> f32 {
        self.train_rows_with(rows, row, settings, rng, true)
    }

    /// [`Mlp::train_rows`], the gradient in padded rows when `use_lanes` and the hidden layer
    /// fits them, else in the flat layout (the reference the padded path must reproduce).
    fn train_rows_with(
        &mut self,
        rows: usize,
        mut row: impl FnMut(usize, &mut [f32]) -> bool,
        settings: TrainSettings,
        rng: &mut impl Rng,
        use_lanes: bool,
    ) -> f32 {
        if rows == 0 {
            return f32::NAN;
        }
        let mut x = vec![0.0f32; self.inputs];
        if !self.trained {
            self.initialise(rng);
            self.trained = true;
        }
        let (b1, w2, b2) = self.offsets();
        let nh = self.hidden;
        let batch = settings.batch_size.max(1);
        let batches = settings.samples.div_ceil(batch).max(1);
        let mut loss_sum = 0.0f32;
        let mut loss_count = 0usize;
        // Hidden layers up to `LANES` wide accumulate the gradient in padded rows (whole
        // vectors, as the forward pass): every element gets the same products added in the same
        // order as in the flat layout, so the same bits; the padding lanes stay unread.
        let lanes = use_lanes && nh <= LANES;
        let mut lane_grad = LaneGrad::new(if lanes { self.inputs } else { 0 });
        for batch_index in 0..batches {
            self.grad.fill(0.0);
            let mut batch_loss = 0.0f32;
            if lanes {
                lane_grad.clear();
                let (mut w_not, mut w_trav) = ([0.0f32; LANES], [0.0f32; LANES]);
                w_not[..nh].copy_from_slice(&self.params[w2..w2 + nh]);
                w_trav[..nh].copy_from_slice(&self.params[w2 + nh..b2]);
                for _ in 0..batch {
                    let r = rng.random_range(0..rows);
                    let label = row(r, &mut x);
                    let (log_p_label, g_trav) = label_loss_gradient(sigmoid(self.logit(&x)), label);
                    batch_loss -= log_p_label;
                    let g_not = -g_trav;
                    let mut a = [0.0f32; LANES];
                    a[..nh].copy_from_slice(&self.hidden_act);
                    lane_grad.add(&x, &a, &w_not, &w_trav, g_not, g_trav);
                }
                lane_grad.write_to(&mut self.grad, nh);
            } else {
                for _ in 0..batch {
                    let r = rng.random_range(0..rows);
                    let label = row(r, &mut x);
                    let (log_p_label, g_trav) = label_loss_gradient(sigmoid(self.logit(&x)), label);
                    batch_loss -= log_p_label;
                    let g_not = -g_trav;
                    self.grad[b2] += g_not;
                    self.grad[b2 + 1] += g_trav;
                    for j in 0..nh {
                        let a = self.hidden_act[j];
                        self.grad[w2 + j] += g_not * a;
                        self.grad[w2 + nh + j] += g_trav * a;
                        self.back[j] =
                            (g_not * self.params[w2 + j] + g_trav * self.params[w2 + nh + j]) * a * (1.0 - a);
                        self.grad[b1 + j] += self.back[j];
                    }
                    for (grad_row, &xi) in self.grad[..b1].chunks_exact_mut(nh).zip(&x) {
                        for (g, bk) in grad_row.iter_mut().zip(&self.back) {
                            *g += bk * xi;
                        }
                    }
                }
            }
            // As in mlpack: the batch loss is the sum over its samples and the L2 term is added
            // once per batch.
            for (k, g) in self.grad.iter_mut().enumerate() {
                let is_weight = k < b1 || (w2..b2).contains(&k);
                if is_weight {
                    *g += settings.l2 * self.params[k];
                }
            }
            for ((p, g), m) in self.params.iter_mut().zip(&self.grad).zip(&mut self.mean_sq) {
                *m = settings.decay * *m + (1.0 - settings.decay) * g * g;
                *p -= settings.step_size * g / (m.sqrt() + settings.epsilon);
            }
            self.lanes_fresh = false;
            if (batches - batch_index) * batch <= rows.max(batch) {
                loss_sum += batch_loss;
                loss_count += batch;
            }
        }
        loss_sum / loss_count.max(1) as f32
    }
}

/// One batch's gradient for a hidden layer at most [`LANES`] wide, in padded rows: `w1` one row
/// per input, then `b1`, the two output rows of `w2` and `b2`.
struct LaneGrad {
    w1: Vec<[f32; LANES]>,
    b1: [f32; LANES],
    w_not: [f32; LANES],
    w_trav: [f32; LANES],
    b2: [f32; 2],
}

impl LaneGrad {
    fn new(inputs: usize) -> Self {
        LaneGrad {
            w1: vec![[0.0; LANES]; inputs],
            b1: [0.0; LANES],
            w_not: [0.0; LANES],
            w_trav: [0.0; LANES],
            b2: [0.0; 2],
        }
    }

    fn clear(&mut self) {
        self.w1.fill([0.0; LANES]);
        self.b1 = [0.0; LANES];
        self.w_not = [0.0; LANES];
        self.w_trav = [0.0; LANES];
        self.b2 = [0.0; 2];
    }

    /// Adds one sample's gradient: inputs `x`, hidden activations `a`, output weights `w_not` /
    /// `w_trav` and the logits' gradients `g_not` / `g_trav` (the flat path's expressions).
    // One index over seven arrays reads as the flat path's loop it must match.
    #[allow(clippy::needless_range_loop)]
    #[inline(always)]
    fn add(
        &mut self,
        x: &[f32],
        a: &[f32; LANES],
        w_not: &[f32; LANES],
        w_trav: &[f32; LANES],
        g_not: f32,
        g_trav: f32,
    ) {
        self.b2[0] += g_not;
        self.b2[1] += g_trav;
        let mut back = [0.0f32; LANES];
        for j in 0..LANES {
            self.w_not[j] += g_not * a[j];
            self.w_trav[j] += g_trav * a[j];
            back[j] = (g_not * w_not[j] + g_trav * w_trav[j]) * a[j] * (1.0 - a[j]);
            self.b1[j] += back[j];
        }
        for (row, &xi) in self.w1.iter_mut().zip(x) {
            for (g, bk) in row.iter_mut().zip(&back) {
                *g += bk * xi;
            }
        }
    }

    /// Writes the gradient into the flat layout of `hidden` units (`w1[inputs][hidden]`, `b1`,
    /// `w2[2][hidden]`, `b2[2]`).
    fn write_to(&self, grad: &mut [f32], hidden: usize) {
        let b1 = hidden * self.w1.len();
        for (flat, row) in grad[..b1].chunks_exact_mut(hidden).zip(&self.w1) {
            flat.copy_from_slice(&row[..hidden]);
        }
        grad[b1..b1 + hidden].copy_from_slice(&self.b1[..hidden]);
        grad[b1 + hidden..b1 + 2 * hidden].copy_from_slice(&self.w_not[..hidden]);
        grad[b1 + 2 * hidden..b1 + 3 * hidden].copy_from_slice(&self.w_trav[..hidden]);
        grad[b1 + 3 * hidden..b1 + 3 * hidden + 2].copy_from_slice(&self.b2);
    }
}

/// One drawn sample's log-likelihood of its label, ln p(label) (floored at ln 1e−7), and the
/// softmax cross-entropy gradient with respect to the "traversable" logit, given the network's
/// p(traversable); the other logit's gradient is its negative. Both gradient layouts of
/// [`Mlp::train_rows`] take it from here.
#[inline(always)]
fn label_loss_gradient(p_trav: f32, label: bool) -> (f32, f32) {
    let target = if label { 1.0 } else { 0.0 };
    let p_label = if label { p_trav } else { 1.0 - p_trav };
    (p_label.max(1e-7).ln(), p_trav - target)
}

/// The logistic function 1 / (1 + e^−x), with [`exp`] below.
#[inline(always)]
fn sigmoid(x: f32) -> f32 {
    1.0 / (1.0 + exp(-x))
}

/// e^x in plain `f32` arithmetic (within 2 ulp of the exact value for |x| < 87; the argument is
/// clamped to [−87, 88], where e^x is a normal number; NaN stays NaN). The same operations in
/// the same order on every instruction set, with no call out, so a loop of it vectorises and
/// gives the same bits vectorised or not, on any x86-64 (libm's `expf` is neither inlined nor
/// guaranteed the same across versions).
///
/// Range reduction x = n·ln 2 + r with |r| ≤ ln 2 / 2 (ln 2 split in two parts so that n·ln2_hi
/// is exact), a degree-6 polynomial for e^r, and 2^n put into the exponent bits.
#[inline(always)]
fn exp(x: f32) -> f32 {
    const LN2_HI: f32 = 0.693_359_4;
    const LN2_LO: f32 = -2.121_944_4e-4;
    // Round to nearest by adding and subtracting 1.5 · 2^23 (|x · log2 e| < 2^22 here): no
    // call to `roundf`, which the SSE2 baseline lacks as an instruction.
    const ROUND: f32 = 12_582_912.0;
    let x = x.clamp(-87.0, 88.0);
    let n = (x * std::f32::consts::LOG2_E + ROUND) - ROUND;
    let r = (x - n * LN2_HI) - n * LN2_LO;
    // Minimax coefficients of (e^r − 1 − r) / r² on [−ln 2 / 2, ln 2 / 2].
    let mut p = 1.987_569_2e-4f32;
    p = p * r + 1.398_199_9e-3;
    p = p * r + 8.333_452e-3;
    p = p * r + 4.166_579_6e-2;
    p = p * r + 1.666_666_5e-1;
    p = p * r + 0.5;
    let e_r = (p * (r * r) + r) + 1.0;
    // n ∈ [−126, 127]: a normal power of two.
    let two_n = f32::from_bits(((n as i32 + 127) << 23) as u32);
    e_r * two_n
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    fn settings(samples: usize) -> TrainSettings {
        TrainSettings { l2: 0.01, step_size: 0.01, decay: 0.99, epsilon: 1e-8, batch_size: 32, samples }
    }

    #[test]
    fn padded_first_layer_gives_the_same_bits_as_the_flat_one() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        for hidden in [1, 7, 10, 16, 17] {
            let mut m = Mlp::new(11, hidden);
            m.initialise(&mut rng);
            // Non-zero biases too, as after training.
            for p in &mut m.params {
                *p += rng.random_range(-0.5..0.5);
            }
            m.trained = true;
            let mut flat_hidden = vec![0.0; hidden];
            for _ in 0..50 {
                let x: Vec<f32> = (0..11).map(|_| rng.random_range(-3.0..3.0)).collect();
                let flat = sigmoid(Mlp::forward(&m.params, 11, &x, &mut flat_hidden));
                let padded = m.probability(&x);
                assert_eq!(flat.to_bits(), padded.to_bits(), "{hidden} hidden units");
                assert_eq!(flat_hidden, m.hidden_act);
            }
            // A parameter change is picked up.
            m.params[0] += 1.0;
            m.lanes_fresh = false;
            let x = [1.0f32; 11];
            let flat = sigmoid(Mlp::forward(&m.params, 11, &x, &mut flat_hidden));
            assert_eq!(flat.to_bits(), m.probability(&x).to_bits());
        }
    }

    /// Training with the gradient in padded rows leaves every parameter, accumulator and the
    /// loss with the bits of the flat gradient's training, whatever the hidden layer's width.
    #[test]
    fn padded_gradient_trains_to_the_same_bits_as_the_flat_one() {
        for hidden in [1, 7, 10, 16, 17] {
            let mut rng = ChaCha8Rng::seed_from_u64(hidden as u64);
            let rows: Vec<(Vec<f32>, bool)> = (0..300)
                .map(|_| {
                    let x: Vec<f32> = (0..11).map(|_| rng.random_range(-3.0..3.0)).collect();
                    let label = x[0] + 0.5 * x[3] > 0.2;
                    (x, label)
                })
                .collect();
            let row = |r: usize, x: &mut [f32]| {
                x.copy_from_slice(&rows[r].0);
                rows[r].1
            };
            let (mut padded, mut flat) = (Mlp::new(11, hidden), Mlp::new(11, hidden));
            for round in 0..3 {
                let seed = 40 + round;
                let a =
                    padded.train_rows_with(rows.len(), row, settings(1000), &mut ChaCha8Rng::seed_from_u64(seed), true);
                let b =
                    flat.train_rows_with(rows.len(), row, settings(1000), &mut ChaCha8Rng::seed_from_u64(seed), false);
                assert_eq!(a.to_bits(), b.to_bits(), "{hidden} hidden units, round {round}");
                let bits = |v: &[f32]| v.iter().map(|p| p.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&padded.params), bits(&flat.params), "{hidden} hidden units, round {round}");
                assert_eq!(bits(&padded.mean_sq), bits(&flat.mean_sq), "{hidden} hidden units, round {round}");
            }
        }
    }

    /// The in-house `exp` stays within 2 ulp of the exact value over the range a sigmoid of the
    /// network's pre-activations uses, and clamps outside it to finite, positive values.
    #[test]
    fn exp_is_within_two_ulp_and_finite() {
        let mut worst = 0.0f64;
        let mut x = -87.0f32;
        while x <= 88.0 {
            let got = exp(x) as f64;
            let exact = (x as f64).exp();
            let ulp = f32::EPSILON as f64 * exact;
            worst = worst.max((got - exact).abs() / ulp);
            x += 0.001_37;
        }
        assert!(worst <= 2.0, "worst error {worst} ulp");
        assert_eq!(exp(0.0), 1.0);
        for x in [-1.0e30f32, -200.0, 200.0, 1.0e30, f32::INFINITY, f32::NEG_INFINITY] {
            let e = exp(x);
            assert!(e.is_finite() && e > 0.0, "exp({x}) = {e}");
        }
        assert!((sigmoid(30.0) - 1.0).abs() < 1e-7 && sigmoid(-120.0) < 1e-30);
    }

    #[test]
    fn training_leaves_no_stale_padded_layer() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let mut m = Mlp::new(2, 10);
        let features = [1.0f32, 0.0, 0.0, 1.0, 0.9, 0.1, 0.1, 0.9];
        let labels = [true, false, true, false];
        m.train(&features, &labels, settings(64), &mut rng);
        let before = m.probability(&[1.0, 0.0]);
        m.train(&features, &labels, settings(64), &mut rng);
        let mut h = vec![0.0; 10];
        let flat = sigmoid(Mlp::forward(&m.params, 2, &[1.0, 0.0], &mut h));
        assert_eq!(m.probability(&[1.0, 0.0]).to_bits(), flat.to_bits());
        assert_ne!(before.to_bits(), flat.to_bits(), "the second round moved the network");
    }

    #[test]
    fn untrained_network_is_undecided() {
        let mut m = Mlp::new(3, 10);
        assert_eq!(m.probability(&[1.0, 2.0, 3.0]), 0.5);
    }

    #[test]
    fn learns_a_separable_colour_labelling() {
        // Colour A (red-ish, normalised) traversable, colour B (blue-ish) not, with noise.
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let mut xs = Vec::new();
        let mut ys = Vec::new();
        for k in 0..200 {
            let a = k % 2 == 0;
            let noise: f32 = rng.random_range(-0.3..0.3);
            if a {
                xs.extend([1.0 + noise, -1.0, 0.2]);
            } else {
                xs.extend([-1.0, 1.0 + noise, 0.2]);
            }
            ys.push(a);
        }
        let mut m = Mlp::new(3, 10);
        let loss = m.train(&xs, &ys, settings(20_000), &mut rng);
        assert!(loss < 0.3, "loss {loss}");
        assert!(m.probability(&[1.0, -1.0, 0.2]) > 0.8);
        assert!(m.probability(&[-1.0, 1.0, 0.2]) < 0.2);
    }

    #[test]
    fn gradient_matches_finite_differences() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let mut m = Mlp::new(2, 3);
        m.initialise(&mut rng);
        let x = [0.7f32, -0.4];
        // Loss for label "traversable" without L2.
        let loss = |p: &[f32]| {
            let mut h = vec![0.0; 3];
            -sigmoid(Mlp::forward(p, 2, &x, &mut h)).ln()
        };
        // Analytic gradient via one step of size ~0 isolates the gradient buffer.
        let s = TrainSettings { l2: 0.0, step_size: 0.0, decay: 0.0, epsilon: 1.0, batch_size: 1, samples: 1 };
        let params = m.params.clone();
        m.trained = true;
        m.train(&[x[0], x[1]], &[true], s, &mut rng);
        for k in 0..params.len() {
            let mut plus = params.clone();
            plus[k] += 1e-3;
            let mut minus = params.clone();
            minus[k] -= 1e-3;
            let numeric = (loss(&plus) - loss(&minus)) / 2e-3;
            assert!((numeric - m.grad[k]).abs() < 2e-3, "param {k}: {numeric} vs {}", m.grad[k]);
        }
    }
}
