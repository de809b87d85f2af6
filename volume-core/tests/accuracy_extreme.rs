//! The extreme suite: the exact intersector (Listing 7.1) must agree with the f64
//! reference on every ray — no missed and no false hits — and the suite must be hard
//! enough that the approximate methods do miss.

use volume_core::intersect::Intersector;
use volume_core::intersect::accuracy::run_extreme_suite;

#[test]
fn exact_intersector_has_no_missed_or_false_hits_on_the_extreme_suite() {
    let results = run_extreme_suite(&[
        Intersector::Exact,
        Intersector::Reference,
        Intersector::Linear,
        Intersector::Neubauer { iterations: 3 },
        Intersector::Schwarze,
    ]);
    let mut total_ref_hits = 0;
    let mut linear_missed = 0;
    for (name, reports) in &results {
        for r in reports {
            eprintln!(
                "{name:50} {:10} rays {:4} ref hits {:4} missed {:3} false {:3} wrong-surface {:2} mean|dt| {:.2e} max|dt| {:.2e}",
                r.intersector.to_string(),
                r.rays,
                r.reference_hits,
                r.missed,
                r.false_hits,
                r.wrong_surface,
                r.mean_abs_dt_cells,
                r.max_abs_dt_cells
            );
        }
        let exact = &reports[0];
        assert_eq!(exact.missed, 0, "{name}: exact missed hits: {exact:?}");
        assert_eq!(exact.false_hits, 0, "{name}: exact false hits: {exact:?}");
        assert_eq!(exact.wrong_surface, 0, "{name}: {exact:?}");
        assert_eq!(exact.far_hits, 0, "{name}: {exact:?}");
        assert!(exact.max_abs_dt_cells < 1e-2, "{name}: {exact:?}");
        let reference = &reports[1];
        assert_eq!((reference.missed, reference.false_hits), (0, 0));
        assert_eq!(reference.max_abs_dt_cells, 0.0);
        total_ref_hits += exact.reference_hits;
        linear_missed += reports[2].missed;
        if name.contains("tangent") {
            assert!(exact.reference_hits > 100, "{name}: tangent rays must hit");
            assert!(reports[2].missed > 0, "linear misses tangent touches");
        }
        if name.starts_with("1×") || name.contains("×1×") || name.contains("×1 volume") {
            assert_eq!(exact.reference_hits, 0, "{name}: no cells, no surface");
        }
        if name.contains("near-tangent") {
            assert!(
                reports[2].missed > 0 && exact.reference_hits >= 240,
                "{name}: near-tangent rays hit, linear misses some"
            );
        }
    }
    assert!(
        total_ref_hits > 2000,
        "the suite must hit: {total_ref_hits}"
    );
    assert!(linear_missed > 0);
}

/// The limits of f32 (near misses by 1e-5…1e-7 of the range, rays grazing iso-valued
/// samples): the f32 methods cannot resolve them, the exact method's f64 path must agree
/// with the reference on every ray.
#[test]
fn exact_intersector_resolves_the_limits_of_f32() {
    use volume_core::intersect::accuracy::{limit_cases, run_cases};
    let results = run_cases(&limit_cases(), &[Intersector::Exact, Intersector::Linear]);
    let mut linear_wrong = 0;
    for (name, reports) in &results {
        let exact = &reports[0];
        assert!(exact.reference_hits > 50, "{name}: {exact:?}");
        assert_eq!(
            (
                exact.missed,
                exact.false_hits,
                exact.far_hits,
                exact.wrong_surface
            ),
            (0, 0, 0, 0),
            "{name}: {exact:?}"
        );
        linear_wrong += reports[1].missed + reports[1].false_hits;
    }
    assert!(linear_wrong > 0, "the cases are beyond the f32 methods");
}

/// The per-ray halves of `compare` give the same report, and every ray's outcome matches
/// the two traces.
#[test]
fn per_ray_scores_agree_with_compare() {
    use volume_core::grid::AnyGridScene;
    use volume_core::intersect::accuracy::{RayOutcome, compare, extreme_suite, score, trace_rays};
    let suite = extreme_suite();
    assert!(suite.len() >= 20, "{} cases", suite.len());
    for case in suite
        .iter()
        .filter(|c| c.name.contains("tangent") || c.name.contains("NaN"))
    {
        let scene = AnyGridScene::new(&case.volume, Intersector::Exact);
        let truth = trace_rays(&scene, &case.rays, &case.isovalues, Intersector::Reference);
        for method in [Intersector::Linear, Intersector::Exact] {
            let got = trace_rays(&scene, &case.rays, &case.isovalues, method);
            let (report, outcomes) = score(&got, &truth);
            let direct = compare(&scene, &case.rays, &case.isovalues, method);
            assert_eq!(
                (report.missed, report.false_hits, report.reference_hits),
                (direct.missed, direct.false_hits, direct.reference_hits),
                "{}",
                case.name
            );
            assert_eq!(report.max_abs_dt_cells, direct.max_abs_dt_cells);
            assert_eq!(outcomes.len(), case.rays.len());
            for ((o, g), t) in outcomes.iter().zip(&got.hits).zip(&truth.hits) {
                match (g, t) {
                    (Some(g), Some(t)) => assert_eq!(
                        *o,
                        RayOutcome::Both {
                            abs_dt_cells: (g.t_cells - t.t_cells).abs(),
                            same_surface: g.surface == t.surface,
                        }
                    ),
                    (None, Some(_)) => assert_eq!(*o, RayOutcome::Missed),
                    (Some(_), None) => assert_eq!(*o, RayOutcome::False),
                    (None, None) => assert_eq!(*o, RayOutcome::NoHit),
                }
            }
        }
    }
}
