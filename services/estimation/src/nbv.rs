//! Next-best-view planning by minimum pose entropy (paper §VI, eq 18–23), and the heuristic
//! policies it is measured against.
//!
//! A candidate view `v` with predicted Fisher information `F_v` (eq 21–22) would leave the pose
//! with covariance `Σ_v = (F_collected + F_v + F_prior)⁻¹` (eq 19–20); its differential
//! entropy is `h = ½ ln((2πe)⁶ |Σ_v|) = ½ (6 ln 2πe − ln |F_collected + F_v + F_prior|)`, and
//! the next view is `v* = argmin h` (eq 23).
//!
//! **The prior.** A part with a continuous symmetry (the Chrome Screw's spin) or a view that
//! sees one face leaves the information rank-deficient, `|F| = 0` and `h = +∞` for every
//! candidate alike. Glint adds a stated Gaussian prior on the pose, the uncertainty of the
//! initial hypothesis (the detector's): it keeps every entropy finite, leaves unobservable
//! directions at the prior's width — equal for every candidate, so they do not sway the
//! choice — and ranks candidates by what they add in the observable subspace. Information is
//! in the refiner's δ coordinates (object frame, translation first; m⁻², rad⁻²).

use nalgebra::{Isometry3, Matrix6};

/// A Gaussian prior on the pose: independent per axis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PosePrior {
    /// σ per translation axis, metres.
    pub sigma_translation_m: f64,
    /// σ per rotation axis, radians.
    pub sigma_rotation_rad: f64,
}

impl Default for PosePrior {
    /// 30 mm and 30° in norm (÷√3 per axis): the largest initial errors `glint eval refine`
    /// perturbs hypotheses by, the paper's detector's range.
    fn default() -> Self {
        Self {
            sigma_translation_m: 30e-3 / 3f64.sqrt(),
            sigma_rotation_rad: 30f64.to_radians() / 3f64.sqrt(),
        }
    }
}

impl PosePrior {
    /// The prior's information, `diag(σ_t⁻² ×3, σ_r⁻² ×3)`.
    pub fn information(&self) -> Matrix6<f64> {
        let t = self.sigma_translation_m.powi(-2);
        let r = self.sigma_rotation_rad.powi(-2);
        Matrix6::from_diagonal(&nalgebra::Vector6::new(t, t, t, r, r, r))
    }

    fn validate(&self) -> Result<(), NbvError> {
        let ok = |s: f64| s.is_finite() && s > 0.0;
        if ok(self.sigma_translation_m) && ok(self.sigma_rotation_rad) {
            Ok(())
        } else {
            Err(NbvError::BadPrior)
        }
    }
}

/// Why a plan could not be made.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum NbvError {
    /// A σ of the [`PosePrior`] is zero, negative or not finite.
    #[error("the pose prior's σ must be finite and positive")]
    BadPrior,
    /// An information matrix has a non-finite entry or is not symmetric to within 1e-9 of its
    /// largest entry (see [`check_symmetric`]).
    #[error("information matrix {which} is not finite and symmetric")]
    NotSymmetric {
        /// Which matrix: `information`, `collected` or `candidates[i]`.
        which: String,
    },
    /// An information matrix has a negative direction, or its sum with the prior (and the
    /// collected information) is not positive definite.
    #[error(
        "information matrix {which} is not positive semi-definite: with the prior added its \
         Cholesky factorisation fails"
    )]
    NotPositive {
        /// Which matrix: `information` or `candidates[i]`.
        which: String,
    },
    /// The candidate list is empty.
    #[error("there are no candidate views")]
    NoCandidates,
    /// A taken view's index is not that of a candidate.
    #[error("taken view {index} is not a candidate (there are {candidates})")]
    TakenOutOfRange {
        /// The offending index.
        index: usize,
        /// Number of candidates.
        candidates: usize,
    },
    /// Every candidate view is already taken: there is nothing left to plan.
    #[error("every candidate view has been taken")]
    AllTaken,
    /// The Max-Distance policy was asked for a view before any was taken; take the first
    /// view another way.
    #[error("no view has been taken yet: the max-distance policy measures from the views taken")]
    NoViewTaken,
}

/// `ln |F|` by Cholesky, or `None` when `F` is not positive definite.
fn ln_det_spd(f: &Matrix6<f64>) -> Option<f64> {
    let chol = f.cholesky()?;
    let l = chol.l_dirty();
    let ln_det = 2.0 * (0..6).map(|i| l[(i, i)].ln()).sum::<f64>();
    ln_det.is_finite().then_some(ln_det)
}

/// Checks that `f` is finite and symmetric to within 1e-9 of its largest entry; `which` names
/// it in the error. What the planner requires of every matrix it is given.
pub fn check_symmetric(f: &Matrix6<f64>, which: &str) -> Result<(), NbvError> {
    let scale = f.amax().max(f64::MIN_POSITIVE);
    let symmetric = f.iter().all(|v| v.is_finite()) && (f - f.transpose()).amax() <= 1e-9 * scale;
    if symmetric {
        Ok(())
    } else {
        Err(NbvError::NotSymmetric {
            which: which.to_string(),
        })
    }
}

/// The entropy of a pose with Fisher information `information` plus `prior`, nats (eq 20):
/// `½ (6 ln 2πe − ln |F + F_prior|)`.
pub fn pose_entropy_nats(information: &Matrix6<f64>, prior: &PosePrior) -> Result<f64, NbvError> {
    prior.validate()?;
    check_symmetric(information, "information")?;
    let ln_det = ln_det_spd(&(information + prior.information())).ok_or(NbvError::NotPositive {
        which: "information".into(),
    })?;
    Ok(0.5 * (6.0 * (2.0 * std::f64::consts::PI * std::f64::consts::E).ln() - ln_det))
}

/// The entropy (nats, eq 20) of a pose known to `sigma_t_m` metres in each translation axis
/// and `sigma_r_rad` radians in each rotation axis, independently:
/// `3 ln 2πe + 3 ln σ_t + 3 ln σ_r`. A stopping threshold stated as a tolerance.
pub fn entropy_of_axis_sigmas(sigma_t_m: f64, sigma_r_rad: f64) -> f64 {
    3.0 * (2.0 * std::f64::consts::PI * std::f64::consts::E).ln()
        + 3.0 * sigma_t_m.ln()
        + 3.0 * sigma_r_rad.ln()
}

/// A minimum-entropy plan.
#[derive(Clone, Debug, PartialEq)]
pub struct Plan {
    /// The index of `v* = argmin h` (eq 23) among the candidates.
    pub chosen: usize,
    /// Per candidate, the entropy after adding its information, nats; `None` for views taken.
    pub entropies_nats: Vec<Option<f64>>,
}

fn check_taken(taken: &[usize], candidates: usize) -> Result<(), NbvError> {
    if candidates == 0 {
        return Err(NbvError::NoCandidates);
    }
    if let Some(&index) = taken.iter().find(|&&i| i >= candidates) {
        return Err(NbvError::TakenOutOfRange { index, candidates });
    }
    Ok(())
}

/// The candidate whose predicted information `candidates[v]` (eq 21–22), added to what the
/// views so far gave (`collected`), leaves the least pose entropy (eq 20, 23). Views in
/// `taken` are not chosen again. Ties go to the lower index.
pub fn plan_next_view(
    collected: &Matrix6<f64>,
    candidates: &[Matrix6<f64>],
    taken: &[usize],
    prior: &PosePrior,
) -> Result<Plan, NbvError> {
    check_taken(taken, candidates.len())?;
    check_symmetric(collected, "collected")?;
    let mut entropies_nats = Vec::with_capacity(candidates.len());
    let mut best: Option<(usize, f64)> = None;
    for (i, f) in candidates.iter().enumerate() {
        if taken.contains(&i) {
            entropies_nats.push(None);
            continue;
        }
        let which = format!("candidates[{i}]");
        check_symmetric(f, &which)?;
        // A candidate must itself be PSD: a negative direction would fake a gain.
        if f.symmetric_eigenvalues().min() < -1e-9 * f.amax().max(f64::MIN_POSITIVE) {
            return Err(NbvError::NotPositive { which });
        }
        let h = pose_entropy_nats(&(collected + f), prior).map_err(|_| NbvError::NotPositive {
            which: which.clone(),
        })?;
        entropies_nats.push(Some(h));
        if best.is_none_or(|(_, hb)| h < hb) {
            best = Some((i, h));
        }
    }
    let (chosen, _) = best.ok_or(NbvError::AllTaken)?;
    Ok(Plan {
        chosen,
        entropies_nats,
    })
}

/// The `k` candidates, best first, whose cheap predicted information (a constant σ_z's: the
/// Jacobians alone, no rendering) added to `collected` leaves the least entropy (eq 20): the
/// shortlist a rendered prediction then ranks by [`plan_next_view`], so that only `k` of the
/// candidates are rendered. Views in `taken` are left out; `k` at or above the number of
/// free candidates keeps them all. Ties go to the lower index.
pub fn shortlist(
    collected: &Matrix6<f64>,
    cheap: &[Matrix6<f64>],
    taken: &[usize],
    prior: &PosePrior,
    k: usize,
) -> Result<Vec<usize>, NbvError> {
    let plan = plan_next_view(collected, cheap, taken, prior)?;
    let mut free: Vec<(usize, f64)> = plan
        .entropies_nats
        .iter()
        .enumerate()
        .filter_map(|(i, h)| h.map(|h| (i, h)))
        .collect();
    // A stable sort keeps ties in index order.
    free.sort_by(|a, b| a.1.total_cmp(&b.1));
    Ok(free.into_iter().take(k).map(|(i, _)| i).collect())
}

/// SplitMix64: a seeded, portable mix for the random policy (no RNG state to carry).
fn splitmix64(mut x: u64) -> u64 {
    x = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    x = (x ^ (x >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    x ^ (x >> 31)
}

/// The Random policy: uniformly one of the `candidates` views not in `taken`, a function of
/// `(seed, step)` only, so a resumed or repeated session chooses the same.
pub fn random_view(
    candidates: usize,
    taken: &[usize],
    seed: u64,
    step: usize,
) -> Result<usize, NbvError> {
    check_taken(taken, candidates)?;
    let free: Vec<usize> = (0..candidates).filter(|i| !taken.contains(i)).collect();
    if free.is_empty() {
        return Err(NbvError::AllTaken);
    }
    let r = splitmix64(splitmix64(seed) ^ step as u64);
    Ok(free[(r % free.len() as u64) as usize])
}

/// The Max-Distance policy: the candidate whose camera centre is furthest from the nearest
/// centre of the views taken (`candidates_t_w_c`: camera → world). Ties go to the lower index.
pub fn max_distance_view(
    candidates_t_w_c: &[Isometry3<f64>],
    taken: &[usize],
) -> Result<usize, NbvError> {
    check_taken(taken, candidates_t_w_c.len())?;
    if taken.is_empty() {
        return Err(NbvError::NoViewTaken);
    }
    let centre = |i: usize| candidates_t_w_c[i].translation.vector;
    let mut best: Option<(usize, f64)> = None;
    for i in (0..candidates_t_w_c.len()).filter(|i| !taken.contains(i)) {
        let nearest = taken
            .iter()
            .map(|&t| (centre(i) - centre(t)).norm())
            .fold(f64::INFINITY, f64::min);
        if best.is_none_or(|(_, d)| nearest > d) {
            best = Some((i, nearest));
        }
    }
    best.map(|(i, _)| i).ok_or(NbvError::AllTaken)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion, Vector6};

    const LN_2PI_E: f64 = 2.837_877_066_409_345_5; // ln(2πe)

    #[test]
    fn axis_sigmas_give_the_entropy_of_their_information() {
        // A pose known to σ_t, σ_r per axis has F = diag(σ_t⁻² ×3, σ_r⁻² ×3): the prior's
        // form, so a prior of those σ with zero measured information has that entropy.
        let (sigma_t_m, sigma_r_rad) = (0.1e-3, 0.1f64.to_radians());
        let prior = PosePrior {
            sigma_translation_m: sigma_t_m,
            sigma_rotation_rad: sigma_r_rad,
        };
        let h = pose_entropy_nats(&Matrix6::zeros(), &prior).unwrap();
        assert!((entropy_of_axis_sigmas(sigma_t_m, sigma_r_rad) - h).abs() < 1e-9 * h.abs());
    }

    #[test]
    fn entropy_of_a_diagonal_information_is_the_closed_form() {
        // With a prior this wide its information is negligible next to F = diag(d):
        // h = ½ (6 ln 2πe − Σ ln d).
        let prior = PosePrior {
            sigma_translation_m: 1e6,
            sigma_rotation_rad: 1e6,
        };
        let d = Vector6::new(1e6, 4e6, 9e6, 1e2, 2e2, 3e2);
        let h = pose_entropy_nats(&Matrix6::from_diagonal(&d), &prior).unwrap();
        let expected = 0.5 * (6.0 * LN_2PI_E - d.iter().map(|v| v.ln()).sum::<f64>());
        assert!((h - expected).abs() < 1e-9, "{h} vs {expected}");
    }

    #[test]
    fn rank_deficient_information_gets_the_prior_in_its_null_space() {
        // A spin about z unobserved: h is the observed part's plus the prior's σ_r there.
        let prior = PosePrior::default();
        let mut f = prior.information() * 1e4;
        f[(5, 5)] = 0.0;
        let h = pose_entropy_nats(&f, &prior).unwrap();
        let diag = f + prior.information();
        let expected = 0.5 * (6.0 * LN_2PI_E - diag.diagonal().iter().map(|v| v.ln()).sum::<f64>());
        assert!((h - expected).abs() < 1e-9);
        assert!(
            pose_entropy_nats(&Matrix6::zeros(), &prior)
                .unwrap()
                .is_finite()
        );
    }

    #[test]
    fn the_plan_picks_the_view_that_observes_the_weak_direction() {
        // Collected information is strong except along x; candidate 1 observes x, 0 and 2
        // observe y (already known), so 1 lowers the entropy most.
        let prior = PosePrior::default();
        let mut collected = Matrix6::from_diagonal(&Vector6::new(0.0, 1e8, 1e8, 1e5, 1e5, 1e5));
        collected[(0, 0)] = 1.0;
        let along = |axis: usize, w: f64| {
            let mut f = Matrix6::zeros();
            f[(axis, axis)] = w;
            f
        };
        let candidates = [along(1, 1e8), along(0, 1e6), along(1, 1e9)];
        let plan = plan_next_view(&collected, &candidates, &[], &prior).unwrap();
        assert_eq!(plan.chosen, 1);
        let h = |i: usize| plan.entropies_nats[i].unwrap();
        assert!(h(1) < h(0) && h(1) < h(2));
        // Taken views are skipped and reported as such.
        let plan = plan_next_view(&collected, &candidates, &[1], &prior).unwrap();
        assert_eq!(plan.entropies_nats[1], None);
        assert_ne!(plan.chosen, 1);
    }

    #[test]
    fn the_shortlist_keeps_the_k_least_entropy_views_in_order() {
        let prior = PosePrior::default();
        // Candidate i observes x with weight w_i: more weight, less entropy.
        let along_x = |w: f64| Matrix6::from_diagonal(&Vector6::new(w, 0.0, 0.0, 0.0, 0.0, 0.0));
        let cheap = [
            along_x(1e6),
            along_x(1e8),
            along_x(1e4),
            along_x(1e8),
            along_x(1e7),
        ];
        let collected = Matrix6::zeros();
        // 1 and 3 tie: the lower index first.
        assert_eq!(
            shortlist(&collected, &cheap, &[], &prior, 3).unwrap(),
            [1, 3, 4]
        );
        assert_eq!(
            shortlist(&collected, &cheap, &[1], &prior, 2).unwrap(),
            [3, 4]
        );
        // k past the free candidates keeps them all; k = 0 keeps none.
        assert_eq!(
            shortlist(&collected, &cheap, &[0], &prior, 99).unwrap(),
            [1, 3, 4, 2]
        );
        assert!(
            shortlist(&collected, &cheap, &[], &prior, 0)
                .unwrap()
                .is_empty()
        );
        // The first of the shortlist is the plan's choice.
        let plan = plan_next_view(&collected, &cheap, &[], &prior).unwrap();
        assert_eq!(plan.chosen, 1);
    }

    #[test]
    fn bad_information_is_rejected_with_its_name() {
        let prior = PosePrior::default();
        let mut asymmetric = Matrix6::zeros();
        asymmetric[(0, 1)] = 1.0;
        let err = plan_next_view(&Matrix6::zeros(), &[asymmetric], &[], &prior).unwrap_err();
        assert_eq!(
            err,
            NbvError::NotSymmetric {
                which: "candidates[0]".into()
            }
        );
        let negative = -Matrix6::identity();
        assert!(matches!(
            plan_next_view(&Matrix6::zeros(), &[negative], &[], &prior),
            Err(NbvError::NotPositive { .. })
        ));
        let mut nan = Matrix6::zeros();
        nan[(2, 2)] = f64::NAN;
        assert!(pose_entropy_nats(&nan, &prior).is_err());
        assert_eq!(
            plan_next_view(&Matrix6::zeros(), &[Matrix6::zeros()], &[0], &prior),
            Err(NbvError::AllTaken)
        );
        assert_eq!(
            plan_next_view(&Matrix6::zeros(), &[], &[], &prior),
            Err(NbvError::NoCandidates)
        );
    }

    fn at(x: f64, y: f64) -> Isometry3<f64> {
        Isometry3::from_parts(Translation3::new(x, y, 0.5), UnitQuaternion::identity())
    }

    #[test]
    fn max_distance_takes_the_furthest_from_every_view_taken() {
        let views = [at(0.0, 0.0), at(0.1, 0.0), at(0.3, 0.0), at(-0.25, 0.0)];
        assert_eq!(max_distance_view(&views, &[0]), Ok(2));
        // From {0, 2}: view 3 is 0.25 from 0, view 1 only 0.1.
        assert_eq!(max_distance_view(&views, &[0, 2]), Ok(3));
        assert_eq!(max_distance_view(&views, &[]), Err(NbvError::NoViewTaken));
        assert_eq!(
            max_distance_view(&views, &[7]),
            Err(NbvError::TakenOutOfRange {
                index: 7,
                candidates: 4
            })
        );
    }

    #[test]
    fn random_is_seeded_uniform_and_never_repeats_a_view() {
        let pick = |seed, step| random_view(10, &[0, 3], seed, step).unwrap();
        assert_eq!(pick(5, 1), pick(5, 1));
        let mut counts = [0usize; 10];
        for seed in 0..8000 {
            counts[pick(seed, 1)] += 1;
        }
        assert_eq!(counts[0] + counts[3], 0);
        // 8 free views, 1000 expected each; binomial σ ≈ 30, so ±150 is 5σ.
        for (i, &c) in counts.iter().enumerate() {
            if i != 0 && i != 3 {
                assert!((850..=1150).contains(&c), "view {i}: {c}");
            }
        }
        assert_eq!(random_view(2, &[0, 1], 1, 1), Err(NbvError::AllTaken));
    }
}
