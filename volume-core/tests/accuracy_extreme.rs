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
        if name.starts_with("1×") {
            assert_eq!(exact.reference_hits, 0, "no cells, no surface");
        }
    }
    assert!(
        total_ref_hits > 2000,
        "the suite must hit: {total_ref_hits}"
    );
    assert!(linear_missed > 0);
}
