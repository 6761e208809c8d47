//! A tape compiled to machine code (`Tape::jit`, the `jit` feature) gives the bits
//! `Tape::eval` gives: on the row, A-and-b and force tapes of every file under
//! `constraints/`, and on random expression trees, at random states sprinkled with special
//! numbers (±0, ±1e300, subnormals, ±∞, NaN; a NaN matches any NaN); and it refuses slices
//! of the wrong lengths as `eval` does.
#![cfg(feature = "jit")]

mod expressions;

use expressions::{Rng, playground, scalar, vector};
use lagrange::derive::derive;
use lagrange::expr::{Graph, Id, Symbol};
use lagrange::model::file::load;
use lagrange::numeric::tape::Tape;
use lagrange::numeric::{JitError, JitTape};
use std::path::{Path, PathBuf};

/// Numbers where IEEE operations and library functions take their special paths.
const SPECIAL: [f64; 14] = [
    0.0,
    -0.0,
    1e300,
    -1e300,
    1e-300,
    5e-324,
    -5e-324,
    2.2250738585072014e-308 / 3.0,
    f64::INFINITY,
    f64::NEG_INFINITY,
    f64::NAN,
    1.0,
    -1.0,
    f64::MAX,
];

/// A state of `n` slots: most in [-2, 2] (masses and lengths positive would be kinder; the
/// compiled code must agree on any number), about one slot in six a special number.
fn state(rng: &mut Rng, n: usize) -> Vec<f64> {
    (0..n).map(|_| if rng.below(6) == 0 { SPECIAL[rng.below(SPECIAL.len())] } else { rng.range(-2.0, 2.0) }).collect()
}

fn same_bits(a: &[f64], b: &[f64]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits() || (x.is_nan() && y.is_nan()))
}

/// The tape compiled, or `None` on a host Cranelift has no code generator for (the one
/// refusal the tests accept, besides a tape too big for a stack frame).
fn jit(tape: &Tape) -> Option<JitTape> {
    match tape.jit() {
        Ok(j) => Some(j),
        Err(JitError::Host(why)) => {
            // Cranelift generates code for these two: there a refusal is a bug.
            if cfg!(any(target_arch = "x86_64", target_arch = "aarch64")) {
                panic!("{why}");
            }
            None
        }
        Err(e) => panic!("{e}"),
    }
}

/// The temporaries a compiled tape may hold (`jit.rs`' `MAX_TEMPORARIES`).
const MAX_TEMPORARIES: usize = 1 << 15;

/// `tape` and its compiled form agree bitwise at `states` random states; returns whether
/// the host compiled it.
fn agrees(what: &str, tape: &Tape, rng: &mut Rng, states: usize) -> bool {
    let Some(j) = jit(tape) else { return false };
    assert_eq!((j.input_len(), j.output_len()), (tape.input_len(), tape.output_len()));
    let mut scratch = tape.scratch();
    let (mut want, mut got) = (vec![0.0; tape.output_len()], vec![0.0; tape.output_len()]);
    for s in 0..states {
        // The first state all ordinary numbers, the rest with specials.
        let x = if s == 0 {
            (0..tape.input_len()).map(|_| rng.range(0.5, 2.0)).collect()
        } else {
            state(rng, tape.input_len())
        };
        tape.eval(&x, &mut scratch, &mut want);
        got.fill(12345.0);
        j.eval(&x, &mut got);
        assert!(same_bits(&got, &want), "{what}, state {s} {x:?}: compiled {got:?}, interpreted {want:?}");
    }
    true
}

fn all_symbols(g: &Graph) -> Vec<Symbol> {
    g.symbols().map(|(s, _)| s).collect()
}

fn toml_files(dir: &Path, into: &mut Vec<PathBuf>) {
    let mut entries: Vec<PathBuf> =
        std::fs::read_dir(dir).expect("a folder").filter_map(|e| e.ok().map(|e| e.path())).collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            toml_files(&p, into);
        } else if p.extension().is_some_and(|x| x == "toml") {
            into.push(p);
        }
    }
}

#[test]
fn compiled_tapes_of_every_file_agree_bitwise_with_eval() {
    let mut files = Vec::new();
    toml_files(Path::new("constraints"), &mut files);
    let mut rng = Rng(0x1616_2026);
    let (mut derived, mut tapes, mut refused) = (0, 0, 0);
    for path in &files {
        let Ok(text) = std::fs::read_to_string(path) else { continue };
        // Files that do not load or derive (constraints/invalid/, say) make no tapes.
        let Ok(loaded) = load(&text) else { continue };
        let Ok(d) = derive(&loaded.system) else { continue };
        derived += 1;
        let syms = all_symbols(&d.graph);
        // The rows (C, Ċ, C̈, raw forms, bias, J of every constraint), each constraint's bias
        // and J alone, A and b, every force together and each alone.
        let mut sets: Vec<(String, Vec<Id>)> = Vec::new();
        let mut rows = Vec::new();
        for (k, dc) in d.constraints.iter().enumerate() {
            rows.extend([dc.c, dc.c_dot, dc.c_ddot, dc.c_dot_raw, dc.c_ddot_raw, dc.bias]);
            rows.extend(dc.jacobian.iter().map(|x| x.1));
            // Big scenes repeat one shape: the first few rows alone are enough.
            if k < 8 {
                sets.push((
                    format!("row {k}"),
                    std::iter::once(dc.bias).chain(dc.jacobian.iter().map(|x| x.1)).collect(),
                ));
            }
        }
        sets.push(("rows".into(), rows));
        sets.push(("A and b".into(), d.a.iter().map(|x| x.2).chain(d.b.iter().copied()).chain(d.lambda).collect()));
        let forces: Vec<Id> = d.forces.iter().flatten().map(|f| f.1).collect();
        sets.extend(forces.iter().take(8).enumerate().map(|(k, &f)| (format!("force {k}"), vec![f])));
        sets.push(("forces".into(), forces));
        for (what, roots) in sets {
            if roots.is_empty() {
                continue;
            }
            let tape = Tape::compile(&d.graph, &roots, &syms).expect("compiles");
            // The whole rows of the 100 x 100 grid hold 177 112 values at once: refused.
            if let Err(JitError::TooLarge(n)) = tape.jit() {
                assert!(n > MAX_TEMPORARIES, "{}: {what} refused with {n} temporaries", path.display());
                refused += 1;
                continue;
            }
            if !agrees(&format!("{}: {what}", path.display()), &tape, &mut rng, 40) {
                return;
            }
            tapes += 1;
        }
    }
    assert!(
        derived >= 60 && tapes >= 350 && refused <= 4,
        "{derived} files derived, {tapes} tapes compiled, {refused} refused"
    );
}

#[test]
fn compiled_random_expressions_agree_bitwise_with_eval() {
    let mut system = playground();
    let mut rng = Rng(0x0016_2026_1207);
    let syms = all_symbols(&system.graph);
    let r = system.bodies[0].position;
    for group in 0..150 {
        let mut roots = Vec::new();
        let mut texts = Vec::new();
        for _ in 0..1 + rng.below(6) {
            let text = if rng.below(2) == 0 { scalar(&mut rng, 4) } else { vector(&mut rng, 4) };
            roots.push(system.expression(&text).unwrap_or_else(|e| panic!("{text}: {e}")));
            texts.push(text);
        }
        let tape = Tape::compile(&system.graph, &roots, &syms).expect("compiles");
        if !agrees(&format!("group {group} {texts:?}"), &tape, &mut rng, 30) {
            return;
        }
    }
    // Outputs that are inputs, constants or one value twice; norms at overflow and underflow.
    let mut roots = Vec::new();
    for text in ["r", "2", "dot(r, r)", "dot(r, r)", "norm(r)", "norm([r.x, r.y, 0])", "r * 0"] {
        roots.push(system.expression(text).expect(text));
    }
    let tape = Tape::compile(&system.graph, &roots, &[r]).expect("compiles");
    agrees("outputs and norms", &tape, &mut rng, 2000);
}

#[test]
fn wrong_lengths_panic_as_eval_does() {
    let mut system = playground();
    let r = system.bodies[0].position;
    let root = system.expression("dot(r, r)").expect("expr");
    let tape = Tape::compile(&system.graph, &[root], &[r]).expect("compiles");
    let Some(j) = jit(&tape) else { return };
    let message = |e: Box<dyn std::any::Any + Send>| {
        e.downcast_ref::<String>()
            .cloned()
            .or_else(|| e.downcast_ref::<&str>().map(|s| s.to_string()))
            .unwrap_or_default()
    };
    for (inputs, outputs, what) in
        [(2, 1, "input length"), (4, 1, "input length"), (3, 0, "output length"), (3, 2, "output length")]
    {
        let compiled =
            std::panic::catch_unwind(|| j.eval(&vec![1.0; inputs], &mut vec![0.0; outputs])).map_err(message);
        let interpreted =
            std::panic::catch_unwind(|| tape.eval(&vec![1.0; inputs], &mut tape.scratch(), &mut vec![0.0; outputs]))
                .map_err(message);
        let (Err(compiled), Err(interpreted)) = (compiled, interpreted) else {
            panic!("{inputs} inputs, {outputs} outputs ran")
        };
        assert!(compiled.contains(what) && interpreted.contains(what), "{compiled} / {interpreted}");
    }
    // The right lengths still run.
    let mut out = [0.0];
    j.eval(&[1.0, 2.0, 3.0], &mut out);
    assert_eq!(out[0], 14.0);
}

#[test]
fn compiled_tapes_are_shared_between_threads_and_freed() {
    fn send_sync<T: Send + Sync>() {}
    send_sync::<JitTape>();
    let mut system = playground();
    let r = system.bodies[0].position;
    let root = system.expression("dot(r, r) * 3 + norm(r)").expect("expr");
    let tape = Tape::compile(&system.graph, &[root], &[r]).expect("compiles");
    // Many compiled and dropped: each frees its code (a leak would show under valgrind, a
    // double free here).
    for _ in 0..200 {
        if jit(&tape).is_none() {
            return;
        }
    }
    let Some(j) = jit(&tape) else { return };
    let mut want = [0.0];
    tape.eval(&[1.0, -2.0, 0.5], &mut tape.scratch(), &mut want);
    std::thread::scope(|s| {
        for _ in 0..4 {
            s.spawn(|| {
                for _ in 0..10_000 {
                    let mut out = [0.0];
                    j.eval(&[1.0, -2.0, 0.5], &mut out);
                    assert_eq!(out[0].to_bits(), want[0].to_bits());
                }
            });
        }
    });
    // Moved to another thread and dropped there.
    std::thread::spawn(move || drop(j)).join().expect("dropped");
}

/// A tape holding more values at once than a stack frame should is refused, not compiled
/// into code that would overflow a thread's stack; one just under the limit runs.
#[test]
fn tapes_too_big_for_a_stack_frame_are_refused() {
    use lagrange::numeric::program::{Op, Program};
    // Value k = value k−1 + x; every value an output, so each lives to the end.
    let tape = |n: usize| {
        let mut ops = vec![Op::Input(0)];
        ops.extend((1..=n as u32).map(|k| Op::Add(k - 1, 0)));
        Tape::from_program(&Program {
            ops,
            n_inputs: 1,
            input_ranges: std::iter::once(0..1).collect(),
            outputs: (1..=n as u32).collect(),
            output_ranges: (0..n).map(|k| k..k + 1).collect(),
        })
    };
    match tape(MAX_TEMPORARIES + 1).jit() {
        Err(JitError::TooLarge(n)) => assert_eq!(n, MAX_TEMPORARIES + 1),
        Err(JitError::Host(_)) => return,
        other => panic!("{other:?}"),
    }
    let small = tape(MAX_TEMPORARIES);
    let Some(j) = jit(&small) else { return };
    // On a thread with a small stack (256 KiB of temporaries and a margin).
    std::thread::Builder::new()
        .stack_size(1 << 20)
        .spawn(move || {
            let mut out = vec![0.0; small.output_len()];
            j.eval(&[0.25], &mut out);
            assert_eq!(out[MAX_TEMPORARIES - 1], 0.25 * (MAX_TEMPORARIES + 1) as f64);
        })
        .expect("a thread")
        .join()
        .expect("ran");
}
