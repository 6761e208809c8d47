//! The rows' tapes compiled to machine code (`RowProgram::compile`, `simulate --compile`):
//! the same numbers bit for bit as the interpreter's, at random states and along whole runs
//! of every constraint file under every solver; `Compile::Auto`'s rule on short and long
//! runs; the CLI option parsed and refused.

mod common;

use lagrange::numeric::simulate::{Compile, Settings};

/// Compiled against interpreted (the `jit` feature).
#[cfg(feature = "jit")]
mod bitwise {
    use super::common;
    use lagrange::numeric::simulate::{Compile, Frame, Settings, Summary};
    use lagrange::numeric::velocity::{Settings as VelocitySettings, Solver};

    /// Every directory of constraint files with scenes.
    const DIRS: [&str; 5] =
        ["constraints", "constraints/hard", "constraints/joints", "constraints/rigid", "constraints/solvers"];

    /// The bits of what an observer sees of a frame: step, time, positions, velocities,
    /// orientations, the rows' C/κ, Ċ/κ and J, λ, and the energy balance.
    fn frame_bits(f: &Frame) -> Vec<u64> {
        let mut bits = vec![f.step, f.time.to_bits()];
        let vectors = f.position.iter().chain(f.velocity).flatten();
        bits.extend(vectors.chain(f.orientations.iter().flatten()).map(|x| x.to_bits()));
        for row in &f.rows.rows {
            bits.extend([row.value.to_bits(), row.rate.to_bits(), row.bias.to_bits()]);
            bits.extend(
                row.jacobian.iter().flat_map(|(b, j)| [*b as u64, j[0].to_bits(), j[1].to_bits(), j[2].to_bits()]),
            );
        }
        bits.extend(f.lambda.iter().map(|x| x.to_bits()));
        bits.extend(f.energy_error.map(f64::to_bits));
        bits
    }

    /// The bits of a summary's final state and figures (all but the wall time and whether it
    /// was compiled).
    fn summary_bits(s: &Summary) -> Vec<u64> {
        let states = s.final_position.iter().chain(&s.final_velocity).flatten();
        let mut bits: Vec<u64> = states.map(|x| x.to_bits()).collect();
        bits.extend([s.steps, s.evaluations, s.max_abs_c.to_bits(), s.max_abs_c_dot.to_bits()]);
        bits.extend([s.final_energy_error.to_bits(), s.max_kinetic.to_bits()]);
        bits.extend(s.energy_rel_drift.map(f64::to_bits));
        bits
    }

    /// A run's frames and its end (the summary, or the error and the summary so far), as bits.
    type Run = (Vec<Vec<u64>>, Result<Vec<u64>, String>, bool);

    fn observed(run: impl FnOnce(&mut dyn FnMut(&Frame) -> Result<(), String>) -> Result<Summary, String>) -> Run {
        let mut frames = Vec::new();
        let result = run(&mut |f| {
            frames.push(frame_bits(f));
            Ok(())
        });
        let compiled = result.as_ref().is_ok_and(|s| s.compiled);
        (frames, result.map(|s| summary_bits(&s)), compiled)
    }

    #[test]
    fn every_file_runs_the_same_bit_for_bit_compiled_or_interpreted_under_every_solver() {
        let (mut runs, mut compiled) = (0, 0);
        for (path, s) in common::scenarios(&DIRS) {
            let tapes = s.program.uncompiled().0;
            // Contacts through some bounces and rests; the rest briefly.
            let contacts = s.system.constraints.iter().any(|c| c.inequality);
            let steps = if contacts { ((s.scene.duration / s.scene.dt) as u64).min(1500) } else { 60 };
            let acceleration = |compile| {
                let settings = Settings { steps, compile, ..s.settings() };
                observed(|observe| {
                    s.simulate(settings, observe).map_err(|f| format!("{} at {:?}", f.error, f.summary.steps))
                })
            };
            let velocity = |solver, compile| {
                let base = VelocitySettings::new(solver, s.scene.dt, 0.0);
                let settings = VelocitySettings { steps, restitution: s.scene.restitution, compile, ..base };
                observed(|observe| {
                    s.simulate_velocity(settings, observe).map_err(|f| format!("{} at {:?}", f.error, f.summary.steps))
                })
            };
            let plans: [(&str, &dyn Fn(Compile) -> Run); 4] = [
                ("exact", &acceleration),
                ("exact-velocity", &|c| velocity(Solver::Exact, c)),
                ("soft-step", &|c| velocity(Solver::SoftStep, c)),
                ("xpbd", &|c| velocity(Solver::Xpbd, c)),
            ];
            for (name, run) in plans {
                let at = format!("{} under {name}", path.display());
                let (never_frames, never, never_compiled) = run(Compile::Never);
                let (always_frames, always, always_compiled) = run(Compile::Always);
                assert!(!never_compiled, "{at}: compiled under Compile::Never");
                // A run that stopped before its first step has no summary to say it.
                assert_eq!(always_compiled, tapes > 0 && always.is_ok(), "{at}: compiled as asked");
                assert_eq!(always_frames.len(), never_frames.len(), "{at}: the frames");
                for (k, (a, n)) in always_frames.iter().zip(&never_frames).enumerate() {
                    assert_eq!(a, n, "{at}: frame {k}");
                }
                assert_eq!(always, never, "{at}: the end");
                runs += 1;
                compiled += usize::from(always_compiled);
            }
        }
        assert!(runs >= 4 * 60 && compiled >= 4 * 50, "{runs} runs, {compiled} compiled");
    }

    /// Every evaluation of the rows, compiled, gives the interpreter's bits at random states,
    /// NaN and infinities among them, on every file's program (a NaN matching any NaN).
    #[test]
    fn compiled_rows_are_the_interpreters_at_random_states() {
        use lagrange::expr::eval::Value;
        use lagrange::numeric::random::Rng;
        use lagrange::numeric::rows::{Rows, State};
        use lagrange::numeric::simulate::initial_state;
        // A NaN matches any NaN (`tests/jit.rs`): which of two NaN operands an addition passes
        // on, and so its sign, is the processor's choice, and Cranelift may swap the operands of
        // a commutative operation. Every other number is compared bit for bit.
        let bits_of = |x: f64| if x.is_nan() { f64::NAN.to_bits() } else { x.to_bits() };
        let bits = |r: &Rows| {
            let mut b: Vec<u64> = r.inverse_mass.iter().map(|&x| bits_of(x)).collect();
            b.extend(r.velocity.iter().chain(&r.force).flatten().map(|&x| bits_of(x)));
            for row in &r.rows {
                b.extend([row.value, row.rate, row.bias].map(bits_of));
                b.extend(
                    row.jacobian.iter().flat_map(|(s, j)| [*s as u64, bits_of(j[0]), bits_of(j[1]), bits_of(j[2])]),
                );
            }
            b
        };
        let mut rng = Rng::new(35);
        let mut checked = 0;
        for (path, s) in common::scenarios(&DIRS) {
            let mut compiled = s.program.clone();
            assert_eq!(compiled.compile(), Ok(()), "{}", path.display());
            assert_eq!(compiled.uncompiled(), (0, 0), "{}", path.display());
            let programs = [&s.program, &compiled];
            let mut scratch = programs.map(|p| p.scratch());
            let mut rows: [Rows; 2] = Default::default();
            let specials = [0.0, -0.0, 1e300, -1e300, 5e-324, f64::INFINITY, f64::NEG_INFINITY, f64::NAN];
            for case in 0..60 {
                let mut env = common::random_env(&s.system, &mut rng);
                let (mut q, mut v, t) = initial_state(&s.system, &env);
                for x in q.iter_mut().chain(&mut v).flatten() {
                    *x += rng.uniform(-0.5, 0.5);
                }
                if case % 3 == 2 {
                    // A special number in a random state slot or symbol.
                    let special = specials[rng.next_u64() as usize % specials.len()];
                    let (n, d) = (rng.next_u64() as usize % q.len().max(1), rng.next_u64() as usize % 3);
                    if let Some(x) = q.get_mut(n) {
                        x[d] = special;
                    }
                    let symbols: Vec<_> = s.system.graph.symbols().map(|(s, _)| s).collect();
                    let symbol = symbols[rng.next_u64() as usize % symbols.len()];
                    if let Some(Value::Scalar(_)) = env.get(symbol) {
                        env.set(symbol, Value::Scalar(special));
                    }
                }
                let state = State { t, q: &q, v: &v };
                let mut got: [Vec<u64>; 2] = Default::default();
                for k in 0..2 {
                    let (p, sc, r) = (programs[k], &mut scratch[k], &mut rows[k]);
                    let mut out = Vec::new();
                    let ok = p.evaluate_into(&s.system, &env, sc, r).is_ok();
                    out.push(u64::from(ok));
                    out.extend(bits(r));
                    out.push(u64::from(sc.finite()));
                    if p.evaluate_state_into(&s.system, &env, state, sc, r).is_ok() {
                        out.extend(bits(r));
                    }
                    if p.evaluate_positions_state_into(&s.system, &env, state, sc, &mut r.rows).is_ok() {
                        out.extend(bits(r));
                        out.push(u64::from(sc.finite()));
                    }
                    if p.evaluate_motion_state_into(&s.system, &env, state, sc, r).is_ok() {
                        out.extend(bits(r));
                        out.push(u64::from(sc.finite()));
                    }
                    got[k] = out;
                }
                assert_eq!(got[1], got[0], "{} case {case}", path.display());
                checked += 1;
            }
        }
        assert!(checked > 3_000, "{checked} states");
    }
}

/// `Compile::Auto` compiles a run long enough to pay the compilation back and not a short
/// one; the rule's break-even grows with the tapes' fixed cost and falls with their size.
#[test]
fn auto_compiles_long_runs_and_not_short_ones() {
    let pendulum = common::scenario("constraints/pendulum.toml");
    let chain = common::scenario("constraints/chain_5.toml");
    for s in [&pendulum, &chain] {
        let (tapes, instructions) = s.program.uncompiled();
        assert_eq!(tapes, 3);
        // The fewest evaluations that pay, found by bisection on the rule itself.
        let (mut short, mut long) = (0u64, 1u64 << 40);
        assert!(Compile::pays(tapes, instructions, long) && !Compile::pays(tapes, instructions, short));
        while long - short > 1 {
            let mid = short + (long - short) / 2;
            if Compile::pays(tapes, instructions, mid) { long = mid } else { short = mid }
        }
        // Monotone: everything past the break-even pays, nothing before it.
        for k in [1, 10, 1_000] {
            assert!(Compile::pays(tapes, instructions, long + k));
            assert!(!Compile::pays(tapes, instructions, short.saturating_sub(k)));
        }
        assert!(!Compile::Never.wanted(tapes, instructions, u64::MAX));
        assert_eq!(Compile::Always.wanted(tapes, instructions, 0), cfg!(feature = "jit"));
        assert_eq!(Compile::Auto.wanted(tapes, instructions, long), cfg!(feature = "jit"));
        assert!(!Compile::Auto.wanted(tapes, instructions, short));
        // A simulation step is two evaluations: a run just short of the break-even stays
        // interpreted, one just past it compiles (with the feature).
        let steps = |evaluations: u64| evaluations / 2;
        for (steps, want) in [(steps(short) - 1, false), (steps(long) + 1, cfg!(feature = "jit"))] {
            let settings = Settings { steps, compile: Compile::Auto, samples: 0, ..s.settings() };
            let summary = s.simulate(settings, &mut |_| Ok(())).expect("runs");
            assert_eq!(summary.compiled, want, "{steps} steps");
        }
    }
    // Nothing to compile: never worth it, and a run says it was not compiled.
    assert!(!Compile::pays(0, 0, u64::MAX));
    let batched = common::scenario("constraints/hard/chain_100.toml");
    assert_eq!(batched.program.uncompiled(), (0, 0));
    let settings = Settings { steps: 3, compile: Compile::Always, ..batched.settings() };
    assert!(!batched.simulate(settings, &mut |_| Ok(())).expect("runs").compiled);
}

#[cfg(feature = "cli")]
fn lagrange(args: &[&str]) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_lagrange")).args(args).output().expect("runs")
}

/// `--compile` takes auto, always and never, with the same results; anything else is
/// refused before the run with exit code 2 and the choices named.
#[cfg(feature = "cli")]
#[test]
fn the_compile_option_is_parsed_and_refused_when_wrong() {
    let without_wall = |out: &std::process::Output| {
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        let mut json: serde_json::Value = serde_json::from_slice(&out.stdout).expect("json");
        json.as_object_mut().expect("an object").remove("wall_seconds");
        json
    };
    for solver in ["exact", "xpbd"] {
        let run = |compile: &str| {
            let args = ["simulate", "constraints/double_pendulum.toml", "--steps", "300", "--format", "json"];
            lagrange(&[&args[..], &["--solver", solver, "--compile", compile]].concat())
        };
        let never = without_wall(&run("never"));
        assert_eq!(without_wall(&run("always")), never, "{solver}");
        assert_eq!(without_wall(&run("auto")), never, "{solver}");
    }
    let help = lagrange(&["simulate", "--help"]);
    let help = String::from_utf8_lossy(&help.stdout);
    assert!(help.contains("--compile"), "{help}");
    assert_eq!(help.contains("this build has no compiler"), !cfg!(feature = "jit"), "{help}");
    for wrong in ["sometimes", "", "ALWAYS"] {
        let out = lagrange(&["simulate", "constraints/pendulum.toml", "--compile", wrong]);
        assert_eq!(out.status.code(), Some(2), "--compile {wrong:?}");
        let err = String::from_utf8_lossy(&out.stderr);
        let what = if wrong.is_empty() {
            "a value is required for '--compile <COMPILE>' but none was supplied".to_string()
        } else {
            format!("invalid value '{wrong}' for '--compile <COMPILE>'")
        };
        assert!(err.contains(&what), "{err}");
        assert!(err.contains("[possible values: auto, always, never]"), "{err}");
        assert!(out.stdout.is_empty(), "--compile {wrong:?}: no run");
    }
}
