//! The compiled tape agrees with the reference interpreter (`expr::eval`): on every derived
//! expression of the files in `constraints/` and on random expression trees, at random
//! states; batched evaluation agrees with single-state evaluation exactly.

mod expressions;

use expressions::{Rng, playground, scalar, vector};
use lagrange::derive::derive;
use lagrange::expr::eval::{Env, Value, eval};
use lagrange::expr::{Graph, Id, Role, Symbol, Ty};
use lagrange::model::file::load;
use lagrange::numeric::program::LowerError;
use lagrange::numeric::tape::{Tape, TapeError};

/// Every symbol of the graph, as the input layout.
fn all_symbols(g: &Graph) -> Vec<Symbol> {
    g.symbols().map(|(s, _)| s).collect()
}

/// A random state: masses positive, everything else in [-2, 2].
fn random_state(g: &Graph, syms: &[Symbol], rng: &mut Rng) -> (Env, Vec<f64>) {
    let mut env = Env::new();
    let mut flat = Vec::new();
    for &s in syms {
        let info = g.symbol(s);
        let value = match info.ty {
            Ty::Scalar => {
                let x = if matches!(info.role, Role::Mass { .. }) || info.name.starts_with('l') {
                    rng.range(0.5, 2.0)
                } else {
                    rng.range(-2.0, 2.0)
                };
                flat.push(x);
                Value::Scalar(x)
            }
            Ty::Vector => {
                let mut v = [0.0; 3];
                for x in v.iter_mut().take(g.dim()) {
                    *x = rng.range(-2.0, 2.0);
                    flat.push(*x);
                }
                Value::Vector(v)
            }
        };
        env.set(s, value);
    }
    (env, flat)
}

fn agree(got: f64, want: f64, tol: f64) -> bool {
    (got.is_nan() && want.is_nan()) || got == want || (got - want).abs() <= tol * want.abs().max(1.0)
}

/// Compares the tape with the interpreter at `states` random states; returns the states'
/// inputs (structure of arrays) and the single-state outputs for batch checks.
fn check(g: &Graph, roots: &[Id], states: usize, seed: u64, tol: f64) -> (Tape, Vec<f64>, Vec<f64>) {
    let syms = all_symbols(g);
    let tape = Tape::compile(g, roots, &syms).expect("compiles");
    let mut rng = Rng(seed);
    let mut scratch = tape.scratch();
    let mut out = vec![0.0; tape.output_len()];
    let (mut soa_in, mut soa_out) = (vec![0.0; tape.input_len() * states], vec![0.0; tape.output_len() * states]);
    for s in 0..states {
        let (env, flat) = random_state(g, &syms, &mut rng);
        tape.eval(&flat, &mut scratch, &mut out);
        let want = eval(g, roots, &env).expect("evaluates");
        for (i, w) in want.iter().enumerate() {
            let w = w.components(g.dim());
            let got = &out[tape.output_range(i)];
            assert_eq!(got.len(), w.len());
            for (x, y) in got.iter().zip(&w) {
                assert!(agree(*x, *y, tol), "root {i} state {s}: tape {x} vs eval {y}");
            }
        }
        for (j, x) in flat.iter().enumerate() {
            soa_in[j * states + s] = *x;
        }
        for (k, x) in out.iter().enumerate() {
            soa_out[k * states + s] = *x;
        }
    }
    (tape, soa_in, soa_out)
}

fn same_bits(a: &[f64], b: &[f64]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits() || (x.is_nan() && y.is_nan()))
}

#[test]
fn tape_agrees_with_eval_on_every_derived_expression() {
    let mut files: Vec<_> = std::fs::read_dir("constraints")
        .expect("constraints/")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    files.sort();
    assert!(!files.is_empty());
    for (n, path) in files.iter().enumerate() {
        let text = std::fs::read_to_string(path).expect("readable");
        let loaded = load(&text).unwrap_or_else(|e| panic!("{}: {e:?}", path.display()));
        let d = derive(&loaded.system).expect("derives");
        let mut roots = Vec::new();
        for dc in &d.constraints {
            roots.extend([dc.c, dc.c_dot, dc.c_ddot, dc.c_dot_raw, dc.c_ddot_raw, dc.bias]);
            roots.extend(dc.jacobian.iter().map(|x| x.1));
        }
        roots.extend(d.a.iter().map(|x| x.2));
        roots.extend(&d.b);
        roots.extend(d.lambda);
        roots.extend(d.forces.iter().flatten().map(|x| x.1));
        let states = 300;
        let (tape, soa_in, soa_out) = check(&d.graph, &roots, states, 0x9e37_79b9 + n as u64, 1e-9);
        let mut batch = vec![0.0; soa_out.len()];
        tape.eval_batch(states, &soa_in, &mut tape.batch_scratch(), &mut batch);
        assert!(same_bits(&batch, &soa_out), "{}: batch differs from single-state", path.display());
    }
}

#[test]
fn tape_agrees_with_eval_on_random_expressions() {
    let mut system = playground();
    let mut rng = Rng(0x2545_f491_4f6c_dd1d);
    let mut roots = Vec::new();
    for _ in 0..400 {
        let text = if rng.below(2) == 0 { scalar(&mut rng, 5) } else { vector(&mut rng, 5) };
        let id = system.expression(&text).unwrap_or_else(|e| panic!("{text}: {e}"));
        roots.push(id);
        // Each expression alone too: a small tape must agree as well as the big shared one.
        let seed = rng.next() | 1;
        let one = std::panic::catch_unwind(|| check(&system.graph, &[id], 5, seed, 1e-9));
        assert!(one.is_ok(), "expression: {text}");
    }
    let (tape, soa_in, soa_out) = check(&system.graph, &roots, 50, 7, 1e-9);
    let mut batch = vec![0.0; soa_out.len()];
    tape.eval_batch(50, &soa_in, &mut tape.batch_scratch(), &mut batch);
    assert!(same_bits(&batch, &soa_out), "batch differs from single-state");
}

/// Single-state evaluation runs its own steps (paired operations, the previous result kept
/// in a machine register, operands computed just before their one reader); the lanes run the
/// instructions as compiled. On random groups of expressions, at random states, the two give
/// the same bits; and one scratch serves tapes with different constants in turn.
#[test]
fn single_state_steps_agree_bitwise_with_the_lanes() {
    let mut system = playground();
    let mut rng = Rng(0x5eed_0016);
    let syms = all_symbols(&system.graph);
    let mut tapes = Vec::new();
    for _ in 0..120 {
        let mut roots = Vec::new();
        for _ in 0..1 + rng.below(6) {
            let text = if rng.below(2) == 0 { scalar(&mut rng, 4) } else { vector(&mut rng, 4) };
            roots.push(system.expression(&text).unwrap_or_else(|e| panic!("{text}: {e}")));
        }
        tapes.push((Tape::compile(&system.graph, &roots, &syms).expect("compiles"), 0));
    }
    // Shapes the random ones may miss: a square sum reading the previous result, a vector
    // scaled by the previous result (plain and negated, as a force λ ∇C), two square sums
    // side by side, dot products of three terms (the first product reading the previous
    // result, or not), the bead's force (7 inputs: the short input copy), and two differences
    // squared and summed with no difference after them (in a chain's rows one follows:
    // `Sub2SqAddSqASub2`).
    for text in [
        "(l + k)^2 + (k * l)^2",
        "((l + k) / m) * r",
        "-(((l + k) / m) * r)",
        "dot(r, r) * l + dot(v, v) * k",
        "dot([l * k, m, t], r)",
        "dot(u, r) * l",
        "(l - k)^2 + (m - l)^2",
    ] {
        let root = system.expression(text).expect("expr");
        tapes.push((Tape::compile(&system.graph, &[root], &syms).expect("compiles"), 0));
    }
    // Row tapes as simulations compile them (A and b of a chain, a rigid joint's rows), whose
    // step sequences the superinstructions were chosen from.
    let files = [
        include_str!("../benches/data/chain_10.toml"),
        include_str!("../constraints/rigid/door_two_hinges.toml"),
        include_str!("../constraints/bead_on_wire.toml"),
    ];
    let mut graphs = Vec::new();
    for text in files {
        let d = derive(&load(text).expect("loads").system).expect("derives");
        let mut sets: Vec<Vec<Id>> = vec![d.a.iter().map(|x| x.2).chain(d.b.iter().copied()).collect()];
        for dc in &d.constraints {
            sets.push(std::iter::once(dc.bias).chain(dc.jacobian.iter().map(|x| x.1)).collect());
        }
        // The constraint forces (the bead's: λ r).
        sets.extend(d.forces.iter().flatten().map(|f| vec![f.1]));
        for roots in sets {
            tapes.push((Tape::compile(&d.graph, &roots, &all_symbols(&d.graph)).expect("compiles"), graphs.len() + 1));
        }
        graphs.push(d.graph);
    }
    // Every step kind of single-state evaluation is among these tapes (their debug form
    // names the steps).
    let listed: String = tapes.iter().map(|(t, _)| format!("{t:?}")).collect();
    for kind in [
        "Add2",
        "Sub2",
        "Mul2",
        "AddA",
        "SubA",
        "SubB",
        "MulA",
        "DivA",
        "DivB",
        "SqAddSqA",
        "MulMulAddA",
        "MulAddC",
        "SubMulA",
        "SubMulB",
        "NegMulA",
        "MulAMulA",
        "MulMulAddNegMulA",
        "MulMulAddANegMulA",
        "Sub2SqAddSqA",
        "MulMulAddAMulAddCMulA",
        "SubMulAMulAddC",
        "MulAddCSubMulA",
        "SqAddSq2",
        "MulMulAddMulAddC",
        "MulMulAddAMulAddC",
        "MulA2",
        "NegMulA2",
        "Sub2Sub2",
        "Sub2SqAddSqASub2",
    ] {
        assert!(listed.contains(&format!("op: {kind},")), "no tape runs the step {kind}");
    }
    let states = 20;
    for (t, (tape, source)) in tapes.iter().enumerate() {
        let graph = if *source == 0 { &system.graph } else { &graphs[source - 1] };
        let syms = all_symbols(graph);
        let mut scratch = tape.scratch();
        let mut soa_in = vec![0.0; tape.input_len() * states];
        let mut single = vec![0.0; tape.output_len() * states];
        let mut out = vec![0.0; tape.output_len()];
        for s in 0..states {
            let (_, flat) = random_state(graph, &syms, &mut rng);
            tape.eval(&flat, &mut scratch, &mut out);
            for (j, x) in flat.iter().enumerate() {
                soa_in[j * states + s] = *x;
            }
            for (k, x) in out.iter().enumerate() {
                single[k * states + s] = *x;
            }
        }
        let mut batch = vec![0.0; single.len()];
        tape.eval_batch(states, &soa_in, &mut tape.batch_scratch(), &mut batch);
        assert!(same_bits(&batch, &single), "tape {t}: single-state steps differ from the lanes");
        // A few states at once (`eval_few`), four at a time through one scratch.
        let mut few = tape.few_scratch::<4>();
        let mut got = vec![0.0; single.len()];
        for group in 0..states / 4 {
            let inputs: Vec<[f64; 4]> =
                (0..tape.input_len()).map(|j| std::array::from_fn(|s| soa_in[j * states + 4 * group + s])).collect();
            let mut out = vec![[0.0; 4]; tape.output_len()];
            tape.eval_few(&inputs, &mut few, &mut out);
            for (k, x) in out.iter().enumerate() {
                got[k * states + 4 * group..][..4].copy_from_slice(x);
            }
        }
        assert!(same_bits(&got, &single), "tape {t}: eval_few differs from single-state evaluation");
    }
    // Two tapes of one register count and different constants through one scratch.
    let r = system.bodies[0].position;
    let two = system.expression("dot(r, r) * 2").expect("expr");
    let three = system.expression("dot(r, r) * 3").expect("expr");
    let (a, b) = (
        Tape::compile(&system.graph, &[two], &[r]).expect("compiles"),
        Tape::compile(&system.graph, &[three], &[r]).expect("compiles"),
    );
    let mut scratch = a.scratch();
    let mut out = [0.0];
    for (tape, want) in [(&a, 28.0), (&b, 42.0), (&a, 28.0), (&a.clone(), 28.0), (&b, 42.0)] {
        tape.eval(&[1.0, 2.0, 3.0], &mut scratch, &mut out);
        assert_eq!(out[0], want);
    }
    let mut few = a.few_scratch::<2>();
    for (tape, want) in [(&a, 28.0), (&b, 42.0), (&a, 28.0), (&b, 42.0)] {
        let mut out = [[0.0; 2]];
        tape.eval_few(&[[1.0, 1.0], [2.0, 2.0], [3.0, 3.0]], &mut few, &mut out);
        assert_eq!(out, [[want, want]]);
    }
}

#[test]
fn norm_does_not_overflow_or_underflow() {
    let mut system = playground();
    let n = system.expression("norm(r)").expect("norm");
    let r = system.bodies[0].position;
    let tape = Tape::compile(&system.graph, &[n], &[r]).expect("compiles");
    for scale in [1e155, 1e300, 1e-160, 1e-300, 1.0] {
        let mut out = [0.0];
        tape.eval(&[3.0 * scale, 0.0, 4.0 * scale], &mut tape.scratch(), &mut out);
        assert!((out[0] / (5.0 * scale) - 1.0).abs() < 1e-15, "norm at scale {scale}: {}", out[0]);
        let mut batch = [0.0; 2];
        let soa = [3.0 * scale, 1.0, 0.0, 0.0, 4.0 * scale, 0.0];
        tape.eval_batch(2, &soa, &mut tape.batch_scratch(), &mut batch);
        assert_eq!(batch, [out[0], 1.0]);
        let mut few = [[0.0; 2]];
        tape.eval_few(&[[3.0 * scale, 1.0], [0.0, 0.0], [4.0 * scale, 0.0]], &mut tape.few_scratch(), &mut few);
        assert_eq!(few, [[out[0], 1.0]]);
    }
}

#[test]
fn missing_input_is_named() {
    let mut system = playground();
    let e = system.expression("dot(r, v) + l").expect("expr");
    let r = system.bodies[0].position;
    let l = system.graph.symbol_named("l").expect("l");
    let err = Tape::compile(&system.graph, &[e], &[r, l]).expect_err("v is missing");
    assert_eq!(err, TapeError::Lower(LowerError::MissingInput("v".into())));
    assert!(err.to_string().contains("`v`"), "{err}");
}

#[test]
fn shared_subexpressions_are_computed_once() {
    let mut system = playground();
    // r·r appears three times; its three products and two sums are computed once.
    let e = system.expression("dot(r, r) + sqrt(dot(r, r)) * dot(r, r)").expect("expr");
    let r = system.bodies[0].position;
    let tape = Tape::compile(&system.graph, &[e], &[r]).expect("compiles");
    // r·r once: x·x + y·y and + z·z (products fused into the sums); then sqrt, and
    // r·r + sqrt·r·r as one multiply-add.
    assert_eq!(tape.instructions(), 4);
}

#[test]
fn large_batches_run_in_parallel_and_agree() {
    let mut system = playground();
    let e = system.expression("cross(r, v) * sin(dot(r, F)) / norm(u)").expect("expr");
    let syms = all_symbols(&system.graph);
    let tape = Tape::compile(&system.graph, &[e], &syms).expect("compiles");
    let n = 3 * lagrange::numeric::tape::PARALLEL_MIN + 17;
    let mut rng = Rng(99);
    let inputs: Vec<f64> = (0..tape.input_len() * n).map(|_| rng.range(-2.0, 2.0)).collect();
    let mut batch = vec![0.0; tape.output_len() * n];
    tape.eval_batch(n, &inputs, &mut tape.batch_scratch(), &mut batch);
    let mut scratch = tape.scratch();
    let mut one = vec![0.0; tape.input_len()];
    let mut out = vec![0.0; tape.output_len()];
    for s in (0..n).step_by(97).chain([n - 1]) {
        for (j, x) in one.iter_mut().enumerate() {
            *x = inputs[j * n + s];
        }
        tape.eval(&one, &mut scratch, &mut out);
        for (k, x) in out.iter().enumerate() {
            assert_eq!(x.to_bits(), batch[k * n + s].to_bits(), "state {s} output {k}");
        }
    }
}

#[test]
fn a_malformed_program_is_refused_not_run() {
    use lagrange::numeric::program::{Op, Program};
    // Value 1 reads value 2 before it exists.
    let p = Program {
        ops: vec![Op::Input(0), Op::Add(0, 2), Op::Call(lagrange::expr::Func::Sqrt, [0, 0])],
        n_inputs: 1,
        input_ranges: std::iter::once(0..1).collect(),
        outputs: vec![1],
        output_ranges: std::iter::once(0..1).collect(),
    };
    let built = std::panic::catch_unwind(|| Tape::from_program(&p));
    assert!(built.is_err(), "a forward reference must not compile to a tape");
}

#[test]
fn batch_outputs_that_are_inputs_constants_or_repeated_agree() {
    let mut system = playground();
    let r = system.bodies[0].position;
    let mut roots = Vec::new();
    for text in ["r", "dot(r, r)", "2", "dot(r, r)", "r", "sqrt(dot(r, r)) * r", "dot(r, r) + 1"] {
        roots.push(system.expression(text).expect(text));
    }
    // Over `r` alone, single-state evaluation reads the inputs in place; over every symbol of
    // the playground (more than 16 slots) it copies them into its registers first.
    let few = Tape::compile(&system.graph, &roots, &[r]).expect("compiles");
    let many = Tape::compile(&system.graph, &roots, &all_symbols(&system.graph)).expect("compiles");
    assert!(few.input_len() <= 16 && many.input_len() > 16);
    for tape in [few, many] {
        outputs_agree(&tape);
    }
}

/// `tape`'s single-state outputs are bitwise its batched ones, at random states.
fn outputs_agree(tape: &Tape) {
    // Odd sizes: partial lanes, and past `PARALLEL_MIN` the parallel path.
    for n in [1, 3, 257, lagrange::numeric::tape::PARALLEL_MIN + 5] {
        let mut rng = Rng(n as u64);
        let inputs: Vec<f64> = (0..tape.input_len() * n).map(|_| rng.range(-2.0, 2.0)).collect();
        let mut batch = vec![f64::NAN; tape.output_len() * n];
        tape.eval_batch(n, &inputs, &mut tape.batch_scratch(), &mut batch);
        let (mut scratch, mut one, mut out) =
            (tape.scratch(), vec![0.0; tape.input_len()], vec![0.0; tape.output_len()]);
        for s in 0..n {
            for (j, x) in one.iter_mut().enumerate() {
                *x = inputs[j * n + s];
            }
            tape.eval(&one, &mut scratch, &mut out);
            for (k, x) in out.iter().enumerate() {
                assert_eq!(x.to_bits(), batch[k * n + s].to_bits(), "n {n} state {s} output {k}");
            }
        }
    }
}
