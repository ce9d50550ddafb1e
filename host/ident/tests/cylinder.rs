//! Real data: the pneumatic cylinder's seal friction, with the ideal piston force `P A` as the
//! simulator's prediction (`../shared/data/pneumatic-cylinder-friction`).

use ocm_ident::{Cause, Config, cylinder, identify};

#[test]
fn friction_explains_most_of_the_ideal_force_error_at_every_pressure() {
    let mut named_first = 0;
    for bar in cylinder::PRESSURES_BAR {
        let rel = format!("{}/{}", cylinder::FOLDER, cylinder::file_name(bar));
        let Some(path) = ocm_datadir::test_data(&rel) else {
            eprintln!("skipping: {rel} not found");
            return;
        };
        let rec = cylinder::load(&path).unwrap();
        let id = identify(&rec, &Config::default()).unwrap();
        let r = &id.report;
        let friction = r
            .candidates
            .iter()
            .find(|c| c.cause == Cause::Friction)
            .expect("friction is a candidate of a record with a position state");
        eprintln!(
            "{bar} bar: causes {:?}, held-out RMSE {:.3} -> {:.3} N ({:.1} %), friction alone {:.1} %, noise {:.3} N",
            r.causes, r.baseline_rmse, r.extended_rmse, r.gain_pct, friction.gain_pct, r.noise_rmse,
        );
        // the residual of `P A` flips with the direction of motion at equal chamber pressure:
        // a seal's friction, not a static map of the pressure
        let dir = r
            .direction_tests
            .first()
            .expect("a direction test for the displacement");
        eprintln!(
            "  direction test: friction force {:.2} +- {:.2} N at equal pressure ({} cells)",
            dir.effect, dir.std_err, dir.cells
        );
        assert!(dir.flips, "{bar} bar: {dir:?}");
        assert!(dir.effect.abs() > 0.5 && dir.effect.abs() < 20.0);
        // the friction extension alone passes every test and cuts the error by more than half
        assert!(friction.accepted, "{bar} bar: {friction:?}");
        assert!(friction.gain_pct >= 50.0, "{bar} bar: {friction:?}");
        assert!(r.gain_pct >= 50.0, "{bar} bar: gain {:.1} %", r.gain_pct);
        if r.causes[0] == Cause::Friction {
            named_first += 1;
            let coulomb = r
                .extension_params
                .iter()
                .find(|p| p.name.starts_with("Coulomb friction"))
                .expect("a Coulomb friction parameter");
            eprintln!(
                "  Coulomb friction {:.2} +- {:.2} N",
                coulomb.value, coulomb.std_err
            );
            assert!(coulomb.value.abs() > 0.5 && coulomb.value.abs() < 20.0);
            assert!(coulomb.std_err > 0.0 && coulomb.std_err < 0.2 * coulomb.value.abs());
        }
    }
    // named first at every pressure: at 5 and 7 bar a cubic in the chamber pressure (which
    // follows the direction of motion) scores higher on the criterion, and the direction
    // test decides
    assert_eq!(
        named_first, 4,
        "friction named first at {named_first} of 4 pressures"
    );
}
