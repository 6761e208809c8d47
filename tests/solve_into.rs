//! The solve into the caller's answer (`solve::solve_into`, `solve::solve_holding_into`):
//! whatever the answer held before — nothing, another file's answer of other sizes, the same
//! answer, numbers that are not finite — every field it writes is the allocating solve's
//! (`solve_with`, `solve_holding`) bit for bit, diagnostics and status too. Over every
//! file's rows under `constraints/` and its folders, at its initial state and at random
//! states, under each method and with random held contacts; and over random chains (the
//! fast path's answer written in place when the sizes repeat, afresh when they change),
//! mixed with rows it declines so that the two paths take turns with one answer.

mod common;

use lagrange::model::file::load;
use lagrange::numeric::random::Rng;
use lagrange::numeric::rows::{Row, Rows};
use lagrange::numeric::solve::{
    Diagnostic, Method, Settings, Solution, Status, chain_serves, solve_holding, solve_holding_into, solve_into,
    solve_with,
};
use lagrange::scenario::Scenario;

/// Equal number for number (bits, so a −0 for a +0 and a NaN's payload count too), the
/// diagnostics by their every field (printed: a NaN in one equals itself), the flags, the
/// contact states and the status.
fn assert_same(a: &Solution, b: &Solution, what: &str) {
    let bits = |x: &[f64]| x.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
    let bits3 = |x: &[[f64; 3]]| x.iter().flat_map(|v| v.map(f64::to_bits)).collect::<Vec<_>>();
    let shown = |d: &[Diagnostic]| d.iter().map(|d| format!("{d:?}")).collect::<Vec<_>>();
    assert_eq!(bits(&a.lambda), bits(&b.lambda), "{what}: λ");
    assert_eq!(bits3(&a.acceleration), bits3(&b.acceleration), "{what}: accelerations");
    assert_eq!(bits3(&a.constraint_force), bits3(&b.constraint_force), "{what}: forces");
    assert_eq!(shown(&a.diagnostics), shown(&b.diagnostics), "{what}: diagnostics");
    assert_eq!((&a.active, a.status, &a.contacts), (&b.active, b.status, &b.contacts), "{what}");
}

/// Every `.toml` file under `dir` and its folders, sorted.
fn files_under(dir: &std::path::Path, out: &mut Vec<std::path::PathBuf>) {
    for entry in std::fs::read_dir(dir).expect("dir") {
        let path = entry.expect("entry").path();
        if path.is_dir() {
            files_under(&path, out);
        } else if path.extension().is_some_and(|e| e == "toml") {
            out.push(path);
        }
    }
}

/// Every file's rows that loads with a scene: at its initial state and at three random states.
fn every_files_rows() -> Vec<(String, Rows)> {
    let mut files = Vec::new();
    files_under(std::path::Path::new("constraints"), &mut files);
    files.sort();
    let mut all = Vec::new();
    for path in files {
        let text = std::fs::read_to_string(&path).expect("file");
        let Some(s) = load(&text).ok().and_then(|loaded| Scenario::new(loaded, &[]).ok()) else {
            continue;
        };
        let at = path.display().to_string();
        if let Ok(rows) = s.program.evaluate(&s.system, &s.env) {
            all.push((format!("{at} (initial)"), rows));
        }
        let mut rng = Rng::new(36);
        for state in 0..3 {
            let env = common::random_env(&s.system, &mut rng);
            if let Ok(rows) = s.program.evaluate(&s.system, &env) {
                all.push((format!("{at} (state {state})"), rows));
            }
        }
    }
    all
}

/// An answer full of numbers that are not finite, of lengths no solve gives, with a
/// diagnostic and the worst status: what `solve_into` must leave nothing of.
fn spoiled() -> Solution {
    Solution {
        lambda: vec![f64::NAN; 7],
        active: vec![true; 3],
        constraint_force: vec![[f64::INFINITY; 3]; 11],
        acceleration: vec![[-0.0; 3]; 2],
        diagnostics: vec![Diagnostic::Closing { constraint: 5 }],
        status: Status::Failed,
        contacts: vec![None; 9],
    }
}

/// Settings of each method.
fn methods() -> Vec<(Method, Settings)> {
    [Method::Auto, Method::Banded, Method::Dense, Method::Sparse]
        .into_iter()
        .map(|method| (method, Settings { method, ..Settings::default() }))
        .collect()
}

#[test]
fn every_files_answer_is_the_allocating_solves_whatever_the_answer_held() {
    let all = every_files_rows();
    assert!(all.len() >= 250, "only {} rows", all.len());
    for (method, settings) in methods() {
        // One answer carried through every file in order, one through them backwards: each
        // solve writes into the last file's answer (other rows, other bodies).
        let (mut forwards, mut backwards) = (Solution::default(), spoiled());
        for ((name, rows), (back_name, back_rows)) in all.iter().zip(all.iter().rev()) {
            let what = format!("{name}, {method:?}");
            let expected = solve_with(rows, &settings);
            let mut fresh = Solution::default();
            solve_into(rows, &settings, &mut fresh);
            assert_same(&fresh, &expected, &format!("{what}: into a fresh answer"));
            solve_into(rows, &settings, &mut forwards);
            assert_same(&forwards, &expected, &format!("{what}: into another file's answer"));
            solve_into(rows, &settings, &mut forwards);
            assert_same(&forwards, &expected, &format!("{what}: into its own answer"));
            let mut spoilt = spoiled();
            solve_into(rows, &settings, &mut spoilt);
            assert_same(&spoilt, &expected, &format!("{what}: into a spoiled answer"));
            let back_expected = solve_with(back_rows, &settings);
            solve_into(back_rows, &settings, &mut backwards);
            assert_same(&backwards, &back_expected, &format!("{back_name}, {method:?}: backwards"));
        }
    }
}

#[test]
fn held_contacts_are_answered_as_the_allocating_solve_answers_them() {
    let mut rng = Rng::new(16);
    let settings = Settings::default();
    let mut out = spoiled();
    let mut contacts = 0;
    for (name, rows) in every_files_rows() {
        // Each inequality row held or not at random (equalities' flags are read as nothing).
        let held: Vec<bool> = rows.rows.iter().map(|r| r.inequality && rng.next_u64().is_multiple_of(2)).collect();
        contacts += held.iter().filter(|h| **h).count();
        let expected = solve_holding(&rows, &settings, &held);
        solve_holding_into(&rows, &settings, &held, &mut out);
        assert_same(&out, &expected, &format!("{name}: held {held:?}"));
    }
    assert!(contacts >= 20, "only {contacts} held rows");
}

/// A random chain of `n` rows in `dim` dimensions: row k acts on slots k − 1 and k (row 0 on
/// slot 0 alone), J of random direction and a magnitude 2^±60, masses 2^±20, random
/// velocities, forces and c terms; the last row an inequality when `contact` (which the
/// fast path declines).
fn random_chain(rng: &mut Rng, n: usize, dim: usize, contact: bool) -> Rows {
    let pow2 = |e: f64| 2f64.powi(e as i32);
    let rows = (0..n)
        .map(|k| {
            let scale = pow2(rng.uniform(-60.0, 60.0));
            let d = rng.normal_vector(dim, scale);
            let mut jacobian = Vec::new();
            if k > 0 {
                jacobian.push((k - 1, d.map(|x| -x)));
            }
            jacobian.push((k, d));
            let inequality = contact && k + 1 == n;
            Row { value: rng.normal() * 1e-3, rate: rng.normal() * 1e-3, bias: rng.normal(), inequality, jacobian }
        })
        .collect();
    Rows {
        dim,
        inverse_mass: (0..n).map(|_| pow2(rng.uniform(-20.0, 20.0))).collect(),
        velocity: (0..n).map(|_| rng.normal_vector(dim, 1.0)).collect(),
        force: (0..n).map(|_| rng.normal_vector(dim, 10.0)).collect(),
        rows,
        axes: Vec::new(),
    }
}

#[test]
fn random_chains_into_one_answer_are_the_allocating_solves_bit_for_bit() {
    let mut rng = Rng::new(36);
    let settings = Settings::default();
    let mut out = Solution::default();
    let (mut served, mut declined, mut repeated) = (0, 0, 0);
    let mut last = 0;
    for case in 0..800 {
        // Sizes that repeat often (the answer written in place) and change (written afresh).
        let n = if case % 3 == 0 { last } else { 1 + (rng.next_u64() % 40) as usize };
        repeated += usize::from(n == last);
        last = n;
        let dim = if case % 4 == 0 { 3 } else { 2 };
        let rows = random_chain(&mut rng, n.max(1), dim, case % 7 == 3);
        let what = format!("case {case}, n = {n}");
        if chain_serves(&rows, &settings) {
            served += 1
        } else {
            declined += 1
        }
        let expected = solve_with(&rows, &settings);
        solve_into(&rows, &settings, &mut out);
        assert_same(&out, &expected, &what);
        solve_into(&rows, &settings, &mut out);
        assert_same(&out, &expected, &format!("{what}: again"));
    }
    assert!(served >= 400 && declined >= 100 && repeated >= 200, "{served} served, {declined} declined, {repeated}");
}
