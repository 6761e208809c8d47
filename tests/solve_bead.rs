//! The numeric solve against the article's closed form for the bead, at states on the wire.

use lagrange::derive::derive;
use lagrange::model::file::load;
use lagrange::model::raw::RawValue;
use lagrange::model::scene::environment;
use lagrange::model::state;
use lagrange::numeric::rows::RowProgram;
use lagrange::numeric::solve::solve;

#[test]
fn bead_force_matches_the_article_at_states_on_the_wire() {
    let text = std::fs::read_to_string("constraints/bead_on_wire.toml").expect("file");
    let loaded = load(&text).expect("valid file");
    let derivation = derive(&loaded.system).expect("derives");
    let program = RowProgram::new(&loaded.system, &derivation, &loaded.scene.forces);
    let (l, m, g) = (2.0, 1.0, -9.81);
    for step in 0..50 {
        let theta = 0.37 * step as f64;
        let speed = 0.2 * step as f64 - 3.0;
        let r = [l * theta.cos(), l * theta.sin()];
        let v = [-speed * theta.sin(), speed * theta.cos()];
        let overrides =
            vec![("r".to_string(), RawValue::Vector(r.to_vec())), ("v".to_string(), RawValue::Vector(v.to_vec()))];
        let overrides = state::values(&loaded.system, &overrides).expect("values of the file's symbols");
        let env = environment(&loaded.system, &loaded.values, &loaded.scene, &overrides).expect("state");
        let rows = program.evaluate(&loaded.system, &env).expect("rows");
        let solution = solve(&rows);
        assert!(solution.diagnostics.is_empty(), "{:?}", solution.diagnostics);
        // The article: F_c = −(m v·v + F·r)/(r·r) r with F = m g.
        let f = [0.0, m * g];
        let lambda = -(m * (v[0] * v[0] + v[1] * v[1]) + f[0] * r[0] + f[1] * r[1]) / (r[0] * r[0] + r[1] * r[1]);
        for (d, rd) in r.iter().enumerate() {
            let expected = lambda * rd;
            let got = solution.constraint_force[0][d];
            assert!((got - expected).abs() <= 1e-12 * (1.0 + expected.abs()), "state {step}: {got} vs {expected}");
        }
    }
}
