//! Magnetometer calibration fits (S-MAG). The error model is the simulator's: a reading is
//! `h = S·B + b + noise`, with `B` the true field in body axes, `S` the soft-iron matrix
//! (`mag.soft_iron`) and `b` the hard iron (`mag.hard_iron`, µT). A calibration is the pair
//! (S, b); its inverse `B = K (h − b)`, `K = S⁻¹`, is what the fits estimate.
//!
//! * [`sphere`] — hard iron only: `|h − b| = r`, linear least squares in (b, r² − |b|²).
//! * [`ellipsoid`] — the seed's baseline: the 10-coefficient quadric by linear least squares,
//!   `KᵀK` from its quadratic part, K the upper-triangular Cholesky factor.
//! * [`swarm`] — the seed's method: 13 unknowns (K, b, λ) by particle swarm on the two
//!   constraints (field magnitude, gravity–field angle), equal weights.
//! * [`levenberg_marquardt`] — ours: the same two constraints by Levenberg–Marquardt, in one of
//!   the [`Model`]s (full symmetric K, diagonal K, hard iron with one scale, 2-D heading plane),
//!   with the parameter covariance.
//!
//! Residuals are dimensionless: `|B|/R − 1` and `f̂·B/R − λ` (λ = cosine of the angle between
//! the specific force and the field, −sin(dip) at rest). The seed writes the first as a
//! squared-norm difference `|B|² − R²`; divided by R² it is the same constraint, and without the
//! division its scale (µT²) would make the equal weights meaningless.
//!
//! Long on purpose: the last 68 lines are the unit tests, beside the code they test; the code is
//! 825 lines (the weighted fit added its weights and the equal-weight entry point).

use auvnav_sim::rng::Rng;
use nalgebra::{DMatrix, DVector, Matrix3, SMatrix, SVector, Vector3};

pub use auvnav_import::mag::MagSample;

/// A calibration `B = K (h − b)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Calibration {
    pub k: Matrix3<f64>,
    pub hard_iron_ut: Vector3<f64>,
    /// Cosine of the gravity–field angle (None when not fitted).
    pub lambda: Option<f64>,
}

impl Calibration {
    pub fn identity() -> Calibration {
        Calibration {
            k: Matrix3::identity(),
            hard_iron_ut: Vector3::zeros(),
            lambda: None,
        }
    }
    /// The calibrated field of a reading (µT).
    pub fn apply(&self, h: &Vector3<f64>) -> Vector3<f64> {
        self.k * (h - self.hard_iron_ut)
    }
    /// The soft-iron matrix S = K⁻¹ (the simulator's `mag.soft_iron`), if K is invertible.
    pub fn soft_iron(&self) -> Option<Matrix3<f64>> {
        self.k.try_inverse()
    }
}

/// Per-residual weights (1/σ²) of a fit (estimated by [`super::weights`]): one for every norm residual, one per sample for the
/// gravity–field residual.
#[derive(Debug, Clone, PartialEq)]
pub struct Weights {
    pub norm: f64,
    /// Per sample; empty means 1 for every sample.
    pub dip: Vec<f64>,
}

impl Weights {
    /// Equal weights (the seed's choice).
    pub fn equal() -> Weights {
        Weights {
            norm: 1.0,
            dip: Vec::new(),
        }
    }
    /// The weight of sample `i`'s gravity–field residual.
    #[inline]
    pub fn dip_of(&self, i: usize) -> f64 {
        self.dip.get(i).copied().unwrap_or(1.0)
    }
}

/// The median of the positive intervals between consecutive readings (s), if any.
pub fn median_interval(samples: &[MagSample]) -> Option<f64> {
    let mut steps: Vec<f64> = samples
        .windows(2)
        .map(|w| w[1].time_s - w[0].time_s)
        .filter(|d| *d > 0.0 && d.is_finite())
        .collect();
    steps.sort_by(f64::total_cmp);
    steps.get(steps.len() / 2).copied()
}

/// Which parameters a Levenberg–Marquardt fit estimates.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Model {
    /// Symmetric K (6) + hard iron (3) + λ.
    Full,
    /// Diagonal K (3) + hard iron (3) + λ.
    Diagonal,
    /// One scale (K = s·I) + hard iron (3) + λ.
    HardIron,
    /// The heading plane: symmetric 2×2 K and the x, y hard iron from the horizontal components
    /// (nearly level data); the z axis is left as read.
    Plane,
    /// No calibration: the readings as they are (chosen when no fit does better on held-out
    /// readings; never fitted by Levenberg–Marquardt).
    None,
}

impl Model {
    pub fn name(self) -> &'static str {
        match self {
            Model::Full => "full (symmetric soft iron + hard iron)",
            Model::Diagonal => "hard iron + diagonal scale",
            Model::HardIron => "hard iron only",
            Model::Plane => "heading-plane 2-D (x, y)",
            Model::None => "no calibration",
        }
    }
}

/// Why a fit could not be made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FitError {
    #[error("{0}")]
    Degenerate(String),
    /// The readings lie in a plane: only the heading-plane model can be fitted.
    #[error("{0}")]
    Planar(String),
}

/// Hard iron only: the sphere `|h − b| = r` by linear least squares. Returns (b, r).
pub fn sphere(samples: &[MagSample]) -> Result<(Vector3<f64>, f64), FitError> {
    if samples.len() < 4 {
        return Err(FitError::Degenerate(format!(
            "{} readings cannot determine a sphere",
            samples.len()
        )));
    }
    // The readings must move: their scatter's largest spread against their magnitude.
    let n = samples.len() as f64;
    let mean = samples.iter().map(|s| s.field_ut).sum::<Vector3<f64>>() / n;
    let scatter = samples
        .iter()
        .map(|s| (s.field_ut - mean) * (s.field_ut - mean).transpose())
        .sum::<Matrix3<f64>>()
        / n;
    let eig = scatter.symmetric_eigenvalues();
    let spread = eig.max().max(0.0).sqrt();
    let level = samples.iter().map(|s| s.field_ut.norm()).sum::<f64>() / n;
    if spread < 0.02 * level.max(1e-9) {
        return Err(FitError::Degenerate(format!(
            "the readings barely change (spread {spread:.3} µT on {level:.1} µT): the recording \
             holds one attitude, no sphere can be fitted; turn the vehicle"
        )));
    }
    if eig.min().max(0.0).sqrt() < 0.02 * spread {
        return Err(FitError::Planar(
            "the readings lie in one plane (one axis of rotation only): no sphere can be fitted"
                .into(),
        ));
    }
    let mut ata = SMatrix::<f64, 4, 4>::zeros();
    let mut atb = SVector::<f64, 4>::zeros();
    for s in samples {
        let h = s.field_ut;
        let row = SVector::<f64, 4>::new(2.0 * h.x, 2.0 * h.y, 2.0 * h.z, 1.0);
        ata += row * row.transpose();
        atb += row * h.norm_squared();
    }
    let x = ata.lu().solve(&atb).ok_or_else(|| {
        FitError::Degenerate(
            "the readings do not span a sphere (all in one plane or one point)".into(),
        )
    })?;
    let b = Vector3::new(x[0], x[1], x[2]);
    let r2 = x[3] + b.norm_squared();
    if !(r2 > 0.0 && r2.is_finite()) {
        return Err(FitError::Degenerate(
            "no real sphere fits the readings".into(),
        ));
    }
    Ok((b, r2.sqrt()))
}

/// The seed's ellipsoid fit: `a1x² + a2y² + a3z² + a4xy + a5xz + a6yz + a7x + a8y + a9z = 1`
/// (the tenth coefficient normalised) by least squares; K = Cholesky factor of `R²·M/k`, scaled
/// so the calibrated field has magnitude `field_ut`.
pub fn ellipsoid(samples: &[MagSample], field_ut: f64) -> Result<Calibration, FitError> {
    // Centre the data for conditioning.
    let n = samples.len() as f64;
    let mean = samples.iter().map(|s| s.field_ut).sum::<Vector3<f64>>() / n;
    let mut ata = SMatrix::<f64, 9, 9>::zeros();
    let mut atb = SVector::<f64, 9>::zeros();
    let scale = samples
        .iter()
        .map(|s| (s.field_ut - mean).norm())
        .sum::<f64>()
        / n;
    if scale.is_nan() || scale <= 0.0 {
        return Err(FitError::Degenerate("all readings are the same".into()));
    }
    for s in samples {
        let h = (s.field_ut - mean) / scale;
        let row = SVector::<f64, 9>::from_column_slice(&[
            h.x * h.x,
            h.y * h.y,
            h.z * h.z,
            h.x * h.y,
            h.x * h.z,
            h.y * h.z,
            h.x,
            h.y,
            h.z,
        ]);
        ata += row * row.transpose();
        atb += row;
    }
    let a = ata.lu().solve(&atb).ok_or_else(|| {
        FitError::Degenerate(
            "the quadric is not determined: the readings do not cover enough attitudes for an \
             ellipsoid"
                .into(),
        )
    })?;
    let m = Matrix3::new(
        a[0],
        a[3] / 2.0,
        a[4] / 2.0,
        a[3] / 2.0,
        a[1],
        a[5] / 2.0,
        a[4] / 2.0,
        a[5] / 2.0,
        a[2],
    );
    let v = Vector3::new(a[6], a[7], a[8]);
    let mi = m.try_inverse().ok_or_else(|| {
        FitError::Degenerate("the fitted quadric is singular (not an ellipsoid)".into())
    })?;
    let c = -0.5 * mi * v;
    let k = 1.0 + c.dot(&(m * c));
    let l = m * (field_ut * field_ut / (k * scale * scale));
    let chol = l.cholesky().ok_or_else(|| {
        FitError::Degenerate(
            "the fitted quadric is not an ellipsoid (not positive definite): too little attitude \
             coverage for the 10-coefficient fit"
                .into(),
        )
    })?;
    Ok(Calibration {
        k: chol.l().transpose(),
        hard_iron_ut: mean + c * scale,
        lambda: None,
    })
}

/// The direction of a specific force, if usable.
fn unit(f: &Option<Vector3<f64>>) -> Option<Vector3<f64>> {
    f.and_then(|f| f.try_normalize(1e-9))
}

/// The seed's fitness of (K, b, λ): ½Σ(|B|²/R² − 1)² + ½Σ(f̂·B/R − λ)², per sample.
pub fn seed_fitness(samples: &[MagSample], field_ut: f64, c: &Calibration) -> f64 {
    fitness_with_units(samples, &unit_forces(samples), field_ut, c)
}

/// [`seed_fitness`] with the unit specific forces computed once ([`unit_forces`]).
fn fitness_with_units(
    samples: &[MagSample],
    units: &[Option<Vector3<f64>>],
    field_ut: f64,
    c: &Calibration,
) -> f64 {
    let lambda = c.lambda.unwrap_or(0.0);
    let inv_r = 1.0 / field_ut;
    let mut sum = 0.0;
    for (s, f) in samples.iter().zip(units) {
        let b = c.apply(&s.field_ut);
        let e1 = b.norm_squared() * inv_r * inv_r - 1.0;
        sum += 0.5 * e1 * e1;
        if let Some(f) = f {
            let e2 = f.dot(&b) * inv_r - lambda;
            sum += 0.5 * e2 * e2;
        }
    }
    sum / samples.len().max(1) as f64
}

/// Particle-swarm settings of the seed method.
#[derive(Debug, Clone, Copy)]
pub struct SwarmSettings {
    pub particles: usize,
    pub iterations: usize,
    pub seed: u64,
}

impl Default for SwarmSettings {
    fn default() -> Self {
        SwarmSettings {
            particles: 100,
            iterations: 150,
            seed: 1,
        }
    }
}

/// The seed method: 13 unknowns x = [K11..K33, b1..b3, λ] by a synchronous particle swarm
/// (inertia 0.729, c1 = c2 = 1.494; the particles of an iteration evaluated in parallel). The search box: K within ±50 % of the scale that maps the sphere fit's
/// radius to R (off-diagonals ±30 %), b within half a radius of the sphere centre, λ ∈ [−1, 1].
/// Deterministic per `settings.seed`. Returns the calibration and the swarm's evaluation count.
pub fn swarm(
    samples: &[MagSample],
    field_ut: f64,
    settings: SwarmSettings,
) -> Result<(Calibration, usize), FitError> {
    let (centre, radius) = sphere(samples)?;
    let s0 = field_ut / radius;
    let mut lo = [0.0; 13];
    let mut hi = [0.0; 13];
    for i in 0..3 {
        for j in 0..3 {
            let k = 3 * i + j;
            if i == j {
                (lo[k], hi[k]) = (0.5 * s0, 1.5 * s0);
            } else {
                (lo[k], hi[k]) = (-0.3 * s0, 0.3 * s0);
            }
        }
        (lo[9 + i], hi[9 + i]) = (centre[i] - 0.5 * radius, centre[i] + 0.5 * radius);
    }
    (lo[12], hi[12]) = (-1.0, 1.0);
    let decode = |x: &[f64; 13]| Calibration {
        k: Matrix3::from_row_slice(&x[..9]),
        hard_iron_ut: Vector3::new(x[9], x[10], x[11]),
        lambda: Some(x[12]),
    };
    let units = unit_forces(samples);
    let fitness = |x: &[f64; 13]| fitness_with_units(samples, &units, field_ut, &decode(x));
    // The particles of one iteration are evaluated in parallel (each fitness depends only on its
    // particle), so the result does not depend on the number of threads.
    let evaluate = |pos: &[[f64; 13]], f: &mut [f64]| {
        use rayon::prelude::*;
        pos.par_iter()
            .zip(f.par_iter_mut())
            .for_each(|(x, y)| *y = fitness(x));
    };
    let mut rng = Rng::new(settings.seed, "calibrate.mag.swarm");
    let n = settings.particles.max(2);
    let mut pos: Vec<[f64; 13]> = (0..n)
        .map(|_| std::array::from_fn(|k| lo[k] + rng.uniform() * (hi[k] - lo[k])))
        .collect();
    let mut vel: Vec<[f64; 13]> = (0..n)
        .map(|_| std::array::from_fn(|k| 0.1 * (2.0 * rng.uniform() - 1.0) * (hi[k] - lo[k])))
        .collect();
    let mut f = vec![0.0; n];
    evaluate(&pos, &mut f);
    let mut evaluations = n;
    let mut pbest = pos.clone();
    let mut pbest_f = f.clone();
    let mut g = 0;
    for i in 1..n {
        if pbest_f[i] < pbest_f[g] {
            g = i;
        }
    }
    let (mut gbest, mut gbest_f) = (pbest[g], pbest_f[g]);
    let (w, c1, c2) = (0.729, 1.494, 1.494);
    // Synchronous swarm: every particle moves with the best of the previous iteration.
    for _ in 0..settings.iterations {
        for i in 0..n {
            for k in 0..13 {
                let (r1, r2) = (rng.uniform(), rng.uniform());
                vel[i][k] = w * vel[i][k]
                    + c1 * r1 * (pbest[i][k] - pos[i][k])
                    + c2 * r2 * (gbest[k] - pos[i][k]);
                let vmax = 0.5 * (hi[k] - lo[k]);
                vel[i][k] = vel[i][k].clamp(-vmax, vmax);
                pos[i][k] = (pos[i][k] + vel[i][k]).clamp(lo[k], hi[k]);
            }
        }
        evaluate(&pos, &mut f);
        evaluations += n;
        for i in 0..n {
            if f[i] < pbest_f[i] {
                pbest_f[i] = f[i];
                pbest[i] = pos[i];
                if f[i] < gbest_f {
                    gbest_f = f[i];
                    gbest = pos[i];
                }
            }
        }
    }
    Ok((decode(&gbest), evaluations))
}

/// A Levenberg–Marquardt result: the calibration, its parameters' standard deviations (in the
/// model's parameter order, see [`parameter_names`]), the normalised condition number of the
/// normal matrix, the residual RMS and the iteration count.
#[derive(Debug, Clone)]
pub struct LmFit {
    pub model: Model,
    pub calibration: Calibration,
    pub parameters: Vec<f64>,
    pub std: Vec<f64>,
    pub condition: f64,
    pub residual_rms: f64,
    pub iterations: usize,
}

/// The names of a model's parameters, in order.
pub fn parameter_names(model: Model) -> &'static [&'static str] {
    match model {
        Model::Full => &[
            "k11", "k22", "k33", "k12", "k13", "k23", "bx", "by", "bz", "lambda",
        ],
        Model::Diagonal => &["k11", "k22", "k33", "bx", "by", "bz", "lambda"],
        Model::HardIron => &["scale", "bx", "by", "bz", "lambda"],
        Model::Plane => &["k11", "k22", "k12", "bx", "by"],
        Model::None => &[],
    }
}

/// The full 10-parameter vector [k11 k22 k33 k12 k13 k23 bx by bz λ] of a model's parameters,
/// and the Jacobian of that map (10 × p).
fn expand(model: Model, p: &[f64]) -> (SVector<f64, 10>, DMatrix<f64>) {
    let mut t = DMatrix::zeros(10, p.len());
    let mut full = SVector::<f64, 10>::zeros();
    match model {
        Model::Full => {
            full.copy_from_slice(p);
            t.fill_with_identity();
        }
        Model::Diagonal => {
            for i in 0..3 {
                full[i] = p[i];
                t[(i, i)] = 1.0;
            }
            for i in 0..4 {
                full[6 + i] = p[3 + i];
                t[(6 + i, 3 + i)] = 1.0;
            }
        }
        Model::HardIron => {
            for i in 0..3 {
                full[i] = p[0];
                t[(i, 0)] = 1.0;
            }
            for i in 0..4 {
                full[6 + i] = p[1 + i];
                t[(6 + i, 1 + i)] = 1.0;
            }
        }
        Model::Plane => unreachable!("the plane model has its own residuals"),
        Model::None => unreachable!("no calibration has no parameters"),
    }
    (full, t)
}

fn k_of(full: &SVector<f64, 10>) -> Matrix3<f64> {
    Matrix3::new(
        full[0], full[3], full[4], full[3], full[1], full[5], full[4], full[5], full[2],
    )
}

/// The unit specific force of each sample (None without one), computed once per fit.
fn unit_forces(samples: &[MagSample]) -> Vec<Option<Vector3<f64>>> {
    samples.iter().map(|s| unit(&s.specific_force)).collect()
}

/// JᵀJ (upper triangle) and Jᵀr accumulated over rows of at most 10 parameters, in fixed-size
/// arrays: the hot loop of the fit allocates nothing and checks no bounds per element.
struct Normal {
    n: usize,
    jtj: [[f64; 10]; 10],
    jtr: [f64; 10],
    ssr: f64,
    count: usize,
}

impl Normal {
    fn new(n: usize) -> Normal {
        Normal {
            n,
            jtj: [[0.0; 10]; 10],
            jtr: [0.0; 10],
            ssr: 0.0,
            count: 0,
        }
    }

    /// Adds one residual `r` with its derivative row and weight `w2` (1/σ²).
    fn add(&mut self, row: &[f64; 10], r: f64, w2: f64) {
        let n = self.n;
        for a in 0..n {
            let ra = row[a] * w2;
            self.jtr[a] += ra * r;
            for (acc, rb) in self.jtj[a][a..n].iter_mut().zip(&row[a..n]) {
                *acc += ra * rb;
            }
        }
        self.ssr += w2 * r * r;
        self.count += 1;
    }

    fn finish(self) -> (DMatrix<f64>, DVector<f64>, f64, usize) {
        let n = self.n;
        let jtj = DMatrix::from_fn(n, n, |a, b| {
            if a <= b {
                self.jtj[a][b]
            } else {
                self.jtj[b][a]
            }
        });
        let jtr = DVector::from_fn(n, |a, _| self.jtr[a]);
        (jtj, jtr, self.ssr, self.count)
    }
}

/// The derivative row of `g · v·(K d)` with respect to the full parameters (K11, K22, K33, K12,
/// K13, K23, b, λ) for a symmetric K: `v` the vector the residual projects on, `d` = reading −
/// hard iron, `kv` = Kᵀv, `lambda` the λ entry.
#[inline]
fn symmetric_row(
    v: &Vector3<f64>,
    d: &Vector3<f64>,
    kv: &Vector3<f64>,
    g: f64,
    lambda: f64,
) -> [f64; 10] {
    [
        v.x * d.x * g,
        v.y * d.y * g,
        v.z * d.z * g,
        (v.x * d.y + v.y * d.x) * g,
        (v.x * d.z + v.z * d.x) * g,
        (v.y * d.z + v.z * d.y) * g,
        -kv.x * g,
        -kv.y * g,
        -kv.z * g,
        lambda,
    ]
}

/// Normal equations of the model at `p`: (JᵀJ, Jᵀr, Σr², residual count), each residual
/// weighted by `w`. `units` holds each sample's unit specific force ([`unit_forces`]).
fn normal_equations(
    model: Model,
    samples: &[MagSample],
    units: &[Option<Vector3<f64>>],
    w: &Weights,
    field_ut: f64,
    horizontal_ut: f64,
    p: &[f64],
) -> (DMatrix<f64>, DVector<f64>, f64, usize) {
    let np = p.len();
    let mut ne = Normal::new(np);
    if model == Model::Plane {
        let k = nalgebra::Matrix2::new(p[0], p[2], p[2], p[1]);
        let b = nalgebra::Vector2::new(p[3], p[4]);
        let mut row = [0.0; 10];
        for s in samples {
            let d = nalgebra::Vector2::new(s.field_ut.x, s.field_ut.y) - b;
            let bb = k * d;
            let nb = bb.norm().max(1e-12);
            let r = nb / horizontal_ut - 1.0;
            // d|B|/dk11 = B1 d1/|B|, dk22 = B2 d2/|B|, dk12 = (B1 d2 + B2 d1)/|B|, db = −KᵀB/|B|.
            let kb = k.transpose() * bb;
            let g = 1.0 / (nb * horizontal_ut);
            row[..5].copy_from_slice(&[
                bb.x * d.x * g,
                bb.y * d.y * g,
                (bb.x * d.y + bb.y * d.x) * g,
                -kb.x * g,
                -kb.y * g,
            ]);
            ne.add(&row, r, w.norm);
        }
        return ne.finish();
    }
    let (full, t) = expand(model, p);
    // The model's parameters from the full ones: row · T (identity for the full model).
    let identity = model == Model::Full;
    let t: [[f64; 10]; 10] =
        std::array::from_fn(|i| std::array::from_fn(|j| if j < np { t[(i, j)] } else { 0.0 }));
    let map = |row: &[f64; 10]| -> [f64; 10] {
        if identity {
            return *row;
        }
        let mut m = [0.0; 10];
        for (i, &x) in row.iter().enumerate() {
            if x != 0.0 {
                for j in 0..np {
                    m[j] += x * t[i][j];
                }
            }
        }
        m
    };
    let k = k_of(&full);
    let b = Vector3::new(full[6], full[7], full[8]);
    let lambda = full[9];
    for (i, (s, f)) in samples.iter().zip(units).enumerate() {
        let d = s.field_ut - b;
        let bb = k * d;
        let nb = bb.norm().max(1e-12);
        let r1 = nb / field_ut - 1.0;
        let kb = k.transpose() * bb;
        ne.add(
            &map(&symmetric_row(&bb, &d, &kb, 1.0 / (nb * field_ut), 0.0)),
            r1,
            w.norm,
        );
        if let Some(f) = f {
            let r2 = f.dot(&bb) / field_ut - lambda;
            let kf = k.transpose() * f;
            ne.add(
                &map(&symmetric_row(f, &d, &kf, 1.0 / field_ut, -1.0)),
                r2,
                w.dip_of(i),
            );
        }
    }
    ne.finish()
}

/// The calibration of a model's parameter vector.
pub fn calibration_of(model: Model, p: &[f64]) -> Calibration {
    if model == Model::Plane {
        return Calibration {
            k: Matrix3::new(p[0], p[2], 0.0, p[2], p[1], 0.0, 0.0, 0.0, 1.0),
            hard_iron_ut: Vector3::new(p[3], p[4], 0.0),
            lambda: None,
        };
    }
    let (full, _) = expand(model, p);
    Calibration {
        k: k_of(&full),
        hard_iron_ut: Vector3::new(full[6], full[7], full[8]),
        lambda: Some(full[9]),
    }
}

/// The start vector of a model from a calibration.
fn start_of(model: Model, c: &Calibration, lambda: f64) -> Vec<f64> {
    let k = &c.k;
    let b = &c.hard_iron_ut;
    match model {
        Model::Full => vec![
            k[(0, 0)],
            k[(1, 1)],
            k[(2, 2)],
            0.5 * (k[(0, 1)] + k[(1, 0)]),
            0.5 * (k[(0, 2)] + k[(2, 0)]),
            0.5 * (k[(1, 2)] + k[(2, 1)]),
            b.x,
            b.y,
            b.z,
            lambda,
        ],
        Model::Diagonal => vec![k[(0, 0)], k[(1, 1)], k[(2, 2)], b.x, b.y, b.z, lambda],
        Model::HardIron => vec![k.diagonal().mean(), b.x, b.y, b.z, lambda],
        Model::Plane => vec![k[(0, 0)], k[(1, 1)], 0.0, b.x, b.y],
        Model::None => Vec::new(),
    }
}

/// The mean of f̂·B/R over the samples with a specific force (λ's start value).
pub fn mean_lambda(samples: &[MagSample], field_ut: f64, c: &Calibration) -> f64 {
    let (mut sum, mut n) = (0.0, 0usize);
    for s in samples {
        if let Some(f) = unit(&s.specific_force) {
            sum += f.dot(&c.apply(&s.field_ut)) / field_ut;
            n += 1;
        }
    }
    if n > 0 { sum / n as f64 } else { 0.0 }
}

/// Levenberg–Marquardt on the model's residuals from `start` with equal weights (R =
/// `field_ut`; the plane model compares the horizontal components with `horizontal_ut`). With no
/// specific force in any sample, λ is not estimated (its row is absent and its start value kept).
pub fn levenberg_marquardt(
    samples: &[MagSample],
    field_ut: f64,
    horizontal_ut: f64,
    model: Model,
    start: &Calibration,
) -> Result<LmFit, FitError> {
    let w = Weights::equal();
    levenberg_marquardt_weighted(samples, field_ut, horizontal_ut, model, start, &w)
}

/// [`levenberg_marquardt`] with each residual weighted by `weights` (1/σ², see
/// [`super::weights`]); the parameters' standard deviations follow from the weights and the
/// weighted residuals.
// Long on purpose: the damped Gauss–Newton loop and the covariance of its result share the
// normal matrix; split, the covariance would have to recompute it.
pub fn levenberg_marquardt_weighted(
    samples: &[MagSample],
    field_ut: f64,
    horizontal_ut: f64,
    model: Model,
    start: &Calibration,
    weights: &Weights,
) -> Result<LmFit, FitError> {
    if samples.is_empty() {
        return Err(FitError::Degenerate("no samples".into()));
    }
    if model == Model::None {
        return Err(FitError::Degenerate(
            "no calibration has no parameters to fit".into(),
        ));
    }
    let lambda0 = mean_lambda(samples, field_ut, start);
    let mut p = start_of(model, start, lambda0);
    let units = unit_forces(samples);
    let has_force = units.iter().any(Option::is_some);
    let np = p.len();
    let (mut jtj, mut jtr, mut ssr, mut m) =
        normal_equations(model, samples, &units, weights, field_ut, horizontal_ut, &p);
    let mut mu = 1e-3;
    let mut iterations = 0;
    for _ in 0..100 {
        iterations += 1;
        let mut a = jtj.clone();
        for i in 0..np {
            a[(i, i)] += mu * jtj[(i, i)].max(1e-12);
        }
        if !has_force && model != Model::Plane {
            // λ has no residual: hold it.
            let l = np - 1;
            a.row_mut(l).fill(0.0);
            a.column_mut(l).fill(0.0);
            a[(l, l)] = 1.0;
        }
        let mut rhs = -jtr.clone();
        if !has_force && model != Model::Plane {
            rhs[np - 1] = 0.0;
        }
        let Some(step) = a.cholesky().map(|c| c.solve(&rhs)) else {
            mu *= 10.0;
            if mu > 1e12 {
                break;
            }
            continue;
        };
        let trial: Vec<f64> = p.iter().zip(step.iter()).map(|(x, d)| x + d).collect();
        let (j2, r2, s2, m2) = normal_equations(
            model,
            samples,
            &units,
            weights,
            field_ut,
            horizontal_ut,
            &trial,
        );
        if s2.is_finite() && s2 < ssr {
            let gain = (ssr - s2) / ssr.max(1e-300);
            p = trial;
            (jtj, jtr, ssr, m) = (j2, r2, s2, m2);
            mu = (mu * 0.3).max(1e-12);
            if gain < 1e-12 || step.norm() < 1e-12 {
                break;
            }
        } else {
            mu *= 10.0;
            if mu > 1e12 {
                break;
            }
        }
    }
    let dof = m.saturating_sub(np).max(1) as f64;
    let sigma2 = ssr / dof;
    // Covariance and condition number on the column-scaled normal matrix.
    let d: Vec<f64> = (0..np).map(|i| jtj[(i, i)].max(1e-300).sqrt()).collect();
    let mut scaled = jtj.clone();
    for i in 0..np {
        for j in 0..np {
            scaled[(i, j)] /= d[i] * d[j];
        }
    }
    if !has_force && model != Model::Plane {
        let l = np - 1;
        scaled.row_mut(l).fill(0.0);
        scaled.column_mut(l).fill(0.0);
        scaled[(l, l)] = 1.0;
    }
    let eig = scaled.clone().symmetric_eigenvalues();
    let (emin, emax) = eig
        .iter()
        .fold((f64::INFINITY, 0.0f64), |(a, b), &e| (a.min(e), b.max(e)));
    let condition = if emin > 0.0 {
        emax / emin
    } else {
        f64::INFINITY
    };
    let std = match scaled.try_inverse() {
        Some(inv) if condition.is_finite() => (0..np)
            .map(|i| (sigma2 * inv[(i, i)].max(0.0)).sqrt() / d[i])
            .collect(),
        _ => vec![f64::INFINITY; np],
    };
    let mut std = std;
    if !has_force && model != Model::Plane {
        std[np - 1] = f64::NAN;
    }
    Ok(LmFit {
        model,
        calibration: calibration_of(model, &p),
        parameters: p,
        std,
        condition,
        residual_rms: (ssr / m.max(1) as f64).sqrt(),
        iterations,
    })
}

/// Roll and pitch (rad) from a specific force in body axes (FRD; at rest f = −g).
pub fn tilt_from_specific_force(f: &Vector3<f64>) -> (f64, f64) {
    let roll = (-f.y).atan2(-f.z);
    let pitch = f.x.atan2(f.y.hypot(f.z));
    (roll, pitch)
}

/// The magnetic heading (rad, east of magnetic north) of a calibrated body field at a roll and
/// pitch (rad): the field levelled by pitch and roll, ψ = −atan2(B_y, B_x).
pub fn magnetic_heading(b: &Vector3<f64>, roll: f64, pitch: f64) -> f64 {
    let (sr, cr) = roll.sin_cos();
    let (sp, cp) = pitch.sin_cos();
    // Ry(pitch) · Rx(roll) · b.
    let y1 = cr * b.y - sr * b.z;
    let z1 = sr * b.y + cr * b.z;
    let x2 = cp * b.x + sp * z1;
    -(y1.atan2(x2))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rot(roll: f64, pitch: f64, yaw: f64) -> Matrix3<f64> {
        nalgebra::Rotation3::from_euler_angles(roll, pitch, yaw).into_inner()
    }

    fn data(s: &Matrix3<f64>, b: &Vector3<f64>, tilt: f64, n: usize) -> Vec<MagSample> {
        let dip: f64 = 60f64.to_radians();
        let field = 50.0 * Vector3::new(dip.cos(), 0.0, dip.sin());
        let mut rng = Rng::new(7, "t");
        (0..n)
            .map(|i| {
                let c = rot(
                    tilt * (2.0 * rng.uniform() - 1.0),
                    tilt * (2.0 * rng.uniform() - 1.0),
                    std::f64::consts::TAU * rng.uniform(),
                );
                let bb = c.transpose() * field;
                MagSample {
                    time_s: i as f64,
                    field_ut: s * bb + b,
                    specific_force: Some(c.transpose() * Vector3::new(0.0, 0.0, -9.8)),
                    angular_rate: None,
                    truth_rpy: None,
                }
            })
            .collect()
    }

    #[test]
    fn fits_recover_a_known_calibration_without_noise() {
        let s = Matrix3::new(1.05, 0.02, -0.01, 0.02, 0.97, 0.03, -0.01, 0.03, 1.01);
        let b = Vector3::new(8.0, -5.0, 12.0);
        let d = data(&s, &b, std::f64::consts::PI, 2000);
        let e = ellipsoid(&d, 50.0).expect("ellipsoid");
        assert!((e.hard_iron_ut - b).norm() < 1e-6, "{}", e.hard_iron_ut);
        let lm = levenberg_marquardt(&d, 50.0, 25.0, Model::Full, &e).expect("lm");
        assert!((lm.calibration.hard_iron_ut - b).norm() < 1e-6);
        let k_true = s.try_inverse().expect("inv");
        assert!(
            (lm.calibration.k - k_true).norm() < 1e-6,
            "{}",
            lm.calibration.k
        );
        assert!((lm.calibration.lambda.expect("l") + 60f64.to_radians().sin()).abs() < 1e-9);
        let (c, r) = sphere(&d).expect("sphere");
        assert!((c - b).norm() < 2.0 && (r - 50.0).abs() < 3.0);
    }

    #[test]
    fn heading_of_a_levelled_field() {
        let dip: f64 = 60f64.to_radians();
        let field = Vector3::new(dip.cos(), 0.0, dip.sin());
        for (r, p, y) in [(0.1, -0.2, 1.0), (-0.3, 0.25, -2.5), (0.0, 0.0, 3.0)] {
            let bb = rot(r, p, y).transpose() * field;
            let h = magnetic_heading(&bb, r, p);
            assert!(
                (auvnav_replay::accuracy::wrap(h - y)).abs() < 1e-12,
                "{h} {y}"
            );
            let f = rot(r, p, y).transpose() * Vector3::new(0.0, 0.0, -9.8);
            let (rr, pp) = tilt_from_specific_force(&f);
            assert!((rr - r).abs() < 1e-12 && (pp - p).abs() < 1e-12);
        }
    }
}
