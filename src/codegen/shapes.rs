//! The step's rows written once per shape: `lagrange generate FILE --solver soft-step|pgs
//! --step-only`, a module with the step and nothing else, for scenes of thousands of rows.
//!
//! A scene repeats a few constraints over many bodies (a grid's 19 701 distance rows are
//! two shapes and a hundred anchored ones), so the rows' code, written row by row, is
//! megabytes. Here the program of the step's roots is lowered once over the whole scene
//! (`numeric::program`, the library's row program: its shared values, and so its numbers,
//! are the tape's), and each row — and each body's 1/m, v and F — is cut out of it as the
//! operations its outputs depend on (its cone). Two cones with the same operations, the same
//! constants and inputs of the same kinds in the same places are one shape: its function
//! (`shape_N`) is written once, over a table of its instances (`SHAPE_N_ITEMS`: which rows
//! or bodies; `SHAPE_N_TABLE`: per instance the bodies whose position or velocity it reads
//! and where its other inputs — parameters, time — start in the flat vector `others`). A
//! cone computes its values with the operations, and in the order, of the whole program, so
//! the rows are the row-by-row module's bit for bit (`tests/generate_step.rs`). A rigid
//! body's I, ω, τ (3D: and its principal axes) are an item of their own kind, written into
//! its angular slots; a row's Jʷ entries follow its linear ones, a 3D body's projected on
//! the slot's axis where `prepare` writes them, as the row-by-row module does. θ, ω and q
//! are inputs of the "other" kind (their places in `others`), and so is a one-argument call
//! of such a scalar (a rigid body's sin θ, cos θ): `others` evaluates it once per state,
//! where each row of a shape would call it again (the same bits either way).
//!
//! Design note: shapes are found on the lowered program, not on the expression graph
//! (`expr::shape` renames derivations): the program is what is written and what fixes the
//! numbers (which divisions share a reciprocal is decided over the whole program), and a
//! parameter (an anchor) is an input here like a body's position, so rows that differ only
//! in their parameters share a shape.
//!
//! Not here: the step itself (`support/step.rs`, `sweep.rs`, one file per solver), the
//! row-by-row module (`rust.rs`), C (`--step-only` is Rust only).

use super::layout::{Layout, Solver};
use super::names::comment_text;
use super::rust::{
    Ctx, Field, Formulas, GenerateError, StepPlaces, StepRoots, array, formula, step_accessors, step_constants,
};
use crate::expr::graph::FastMap;
use crate::expr::{Func, Graph, Ty};
use crate::model::system::System;
use crate::numeric::program::{Op, Program, Val};
use std::cell::Cell;
use std::fmt::Write;

/// Where a shape's input comes from, for one instance: a component of the position or
/// velocity of the instance's `b`-th body, or of its `o`-th other input symbol.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
enum Source {
    Position(u32, u32),
    Velocity(u32, u32),
    Other(u32, u32),
}

/// What an input slot of the module is: a body's position or velocity component, or a
/// component of another symbol (its field's index among the module's fields).
#[derive(Clone, Copy)]
enum Slot {
    Position(usize, u32),
    Velocity(usize, u32),
    Other(usize, u32),
}

/// An input of the flat vector `others`: a field of the module (all its components), or a
/// one-argument function of one scalar component of a field (`sin θ`, `cos θ` of a rigid
/// body's angle), evaluated once per `prepare` instead of once per row that reads it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
enum Other {
    Field(usize),
    Call(Func, usize, u32),
}

impl Other {
    /// How many numbers it takes in `others`.
    fn width(self, widths: &[usize]) -> usize {
        match self {
            Other::Field(f) => widths[f],
            Other::Call(..) => 1,
        }
    }
}

/// What a shape's instances are, so what its outputs are.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
enum Kind {
    /// A body: m, v, F.
    Body,
    /// A rigid body's angular slots: I, ω, τ (2D, scalars), and in 3D its principal axes.
    Rigid,
    /// A row with this many linear Jacobian entries: C, Ċ (not on a steady row, the flag:
    /// `StepRoots::steady`), each entry's J, then its Jʷ (one per angular slot).
    Row(usize, bool),
}

impl Kind {
    fn is_row(&self) -> bool {
        matches!(self, Kind::Row(..))
    }
}

/// A shape: its program over local inputs, and its instances.
struct Shape {
    ops: Vec<Op>,
    sources: Vec<Source>,
    outputs: Vec<Val>,
    kind: Kind,
    /// Bodies and other symbols each instance names (the table's width is their sum).
    bodies: usize,
    others: usize,
    /// The rows (or bodies) it is the shape of, and per instance its table entries.
    items: Vec<usize>,
    table: Vec<u32>,
}

/// The key two cones share when they are one shape.
type Key = (Kind, Vec<Op>, Vec<Source>, Vec<Val>);

/// The call `op` as an input of `others` when it is a one-argument function of a scalar
/// component of a field other than a body's position or velocity (`sin θ`): the same
/// function of the same number, so the same bits, once per state instead of once per row.
fn hoisted(p: &Program, slots: &[Slot], op: Op) -> Option<Other> {
    let Op::Call(f, args) = op else { return None };
    let Op::Input(j) = p.ops[args[0] as usize] else { return None };
    match slots[j as usize] {
        Slot::Other(field, c) if f.arity() == 1 => Some(Other::Call(f, field, c)),
        _ => None,
    }
}

/// Cuts `items` (each a list of roots, as indices into the program's roots) out of the
/// program `p` and groups them by shape. `others` maps an other input (a field, or a
/// function of a field's component: [`hoisted`]) to its first slot in the flat vector of
/// other inputs, assigning one at first use.
#[allow(clippy::too_many_arguments)]
fn shapes(
    p: &Program,
    slots: &[Slot],
    items: &[(Kind, Vec<usize>)],
    others: &mut FastMap<Other, u32>,
    widths: &[usize],
    next_other: &mut u32,
    groups: &mut FastMap<Key, usize>,
    out: &mut Vec<Shape>,
) {
    let mut mark = vec![u32::MAX; p.ops.len()];
    let mut stack = Vec::new();
    let mut cone = Vec::new();
    for (item, (kind, roots)) in items.iter().enumerate() {
        // The item's cone, in program order.
        cone.clear();
        let outputs: Vec<Val> =
            roots.iter().flat_map(|&r| p.outputs[p.output_ranges[r].clone()].iter().copied()).collect();
        stack.extend(outputs.iter().copied());
        while let Some(v) = stack.pop() {
            if mark[v as usize] == item as u32 {
                continue;
            }
            mark[v as usize] = item as u32;
            cone.push(v);
            // A hoisted call is a leaf of the cone: its argument is read in `others`.
            if hoisted(p, slots, p.ops[v as usize]).is_none() {
                stack.extend(p.ops[v as usize].operands());
            }
        }
        cone.sort_unstable();
        // Renumbered: local values, local inputs by first use, local bodies and others.
        let mut local: FastMap<Val, Val> = FastMap::default();
        let (mut ops, mut sources) = (Vec::with_capacity(cone.len()), Vec::new());
        let (mut bodies, mut other_fields): (Vec<usize>, Vec<Other>) = (Vec::new(), Vec::new());
        let mut other_at = |o: Other| {
            other_fields.iter().position(|&x| x == o).unwrap_or_else(|| {
                other_fields.push(o);
                other_fields.len() - 1
            }) as u32
        };
        for &v in &cone {
            let op = match p.ops[v as usize] {
                op if hoisted(p, slots, op).is_some() => {
                    let at = hoisted(p, slots, op).map_or(0, &mut other_at);
                    sources.push(Source::Other(at, 0));
                    Op::Input(sources.len() as u32 - 1)
                }
                Op::Input(j) => {
                    let source = match slots[j as usize] {
                        Slot::Position(b, c) | Slot::Velocity(b, c) => {
                            let at = bodies.iter().position(|&x| x == b).unwrap_or_else(|| {
                                bodies.push(b);
                                bodies.len() - 1
                            }) as u32;
                            if matches!(slots[j as usize], Slot::Position(..)) {
                                Source::Position(at, c)
                            } else {
                                Source::Velocity(at, c)
                            }
                        }
                        Slot::Other(f, c) => Source::Other(other_at(Other::Field(f)), c),
                    };
                    sources.push(source);
                    Op::Input(sources.len() as u32 - 1)
                }
                op => renumber(op, &local),
            };
            local.insert(v, ops.len() as Val);
            ops.push(op);
        }
        let local_outputs: Vec<Val> = outputs.iter().map(|o| local[o]).collect();
        let key: Key = (*kind, ops, sources, local_outputs);
        let id = *groups.entry(key).or_insert_with_key(|key| {
            out.push(Shape {
                kind: *kind,
                ops: key.1.clone(),
                sources: key.2.clone(),
                outputs: key.3.clone(),
                bodies: bodies.len(),
                others: other_fields.len(),
                items: Vec::new(),
                table: Vec::new(),
            });
            out.len() - 1
        });
        let shape = &mut out[id];
        shape.items.push(item);
        shape.table.extend(bodies.iter().map(|&b| b as u32));
        for &f in &other_fields {
            let at = *others.entry(f).or_insert_with(|| {
                let at = *next_other;
                *next_other += f.width(widths) as u32;
                at
            });
            shape.table.push(at);
        }
    }
}

/// `op` with its operands renumbered by `local`.
fn renumber(op: Op, local: &FastMap<Val, Val>) -> Op {
    let m = |v: Val| local[&v];
    match op {
        Op::Input(_) | Op::Const(_) => op,
        Op::Add(a, b) => Op::Add(m(a), m(b)),
        Op::Sub(a, b) => Op::Sub(m(a), m(b)),
        Op::Mul(a, b) => Op::Mul(m(a), m(b)),
        Op::Div(a, b) => Op::Div(m(a), m(b)),
        Op::Neg(a) => Op::Neg(m(a)),
        Op::Powi(a, n) => Op::Powi(m(a), n),
        Op::Powf(a, b) => Op::Powf(m(a), m(b)),
        Op::Call(f, args) => Op::Call(f, args.map(m)),
        Op::Norm2(a, b) => Op::Norm2(m(a), m(b)),
        Op::Norm3(a, b, c) => Op::Norm3(m(a), m(b), m(c)),
    }
}

/// What each input slot of the module is, in the order of its fields (`slot_exprs`'s).
fn slot_kinds(g: &Graph, system: &System, fields: &[Field]) -> (Vec<Slot>, Vec<usize>) {
    let (mut slots, mut widths) = (Vec::new(), Vec::new());
    for (f, field) in fields.iter().enumerate() {
        let width = if g.is_quaternion(field.symbol) {
            4
        } else if g.symbol(field.symbol).ty == Ty::Vector {
            g.dim()
        } else {
            1
        };
        widths.push(width);
        let position = system.bodies.iter().position(|b| b.position == field.symbol);
        let velocity = system.bodies.iter().position(|b| b.velocity == field.symbol);
        for c in 0..width as u32 {
            slots.push(match (position, velocity) {
                (Some(b), _) => Slot::Position(b, c),
                (_, Some(b)) => Slot::Velocity(b, c),
                _ => Slot::Other(f, c),
            });
        }
    }
    (slots, widths)
}

/// The module's step part with its rows by shape: the step's constants, the flat vector of
/// other inputs (`others`), each shape's function and tables, `prepare` over them, and the
/// state's accessors. `step` holds the step's roots in `step_fns`' order (per body m, v, F;
/// per rigid body I, ω, τ and in 3D its axes; per row C, Ċ, c, J, then Jʷ per angular slot).
#[allow(clippy::too_many_arguments)]
pub(super) fn step_by_shape(
    out: &mut String,
    ctx: &Ctx<'_>,
    system: &System,
    fields: &[Field],
    solver: Solver,
    inverse_scales: &[f64],
    places: &StepPlaces<'_>,
    formulas: &Formulas,
    layout: &Layout,
    step: &StepRoots,
    arrays: bool,
) -> Result<(), GenerateError> {
    let g = ctx.g;
    let (n, k, dim) = (layout.bodies, layout.constraints, layout.dim);
    let (starts, entry_at) = step_constants(out, solver, inverse_scales, step, formulas, layout);
    // Rows whose entries the step keeps in the derivation's order store entry e of a row at
    // `ROW_START[i] + e`, the others through `ENTRY_AT` (`velocity::entry_order`).
    let in_order = entry_at.iter().enumerate().all(|(e, &at)| e == at);
    let p = Program::lower_in(g, &step.roots, ctx.inputs)?;
    let (slots, widths) = slot_kinds(g, system, fields);
    // Items: per body its m, v, F roots; per rigid body I, ω, τ (and in 3D its three axes);
    // per row C, Ċ, its J entries and its Jʷ, one per angular slot (c is not read).
    let bodies: Vec<(Kind, Vec<usize>)> = (0..n).map(|i| (Kind::Body, vec![3 * i, 3 * i + 1, 3 * i + 2])).collect();
    let three = step.three() > 0;
    let per_rigid = if three { 6 } else { 3 };
    let rigid: Vec<(Kind, Vec<usize>)> = (0..step.turns.len())
        .map(|r| (Kind::Rigid, (0..per_rigid).map(|x| 3 * n + per_rigid * r + x).collect()))
        .collect();
    let mut rows = Vec::with_capacity(k);
    let mut at = 3 * n + per_rigid * step.turns.len();
    for ((dirs, angular), &steady) in formulas.jacobian.iter().zip(&step.angular_slots).zip(&step.steady) {
        let entries = dirs.len() + angular.len();
        // A steady row's Ċ is not read: its cone leaves it out.
        let mut item = if steady { vec![at] } else { vec![at, at + 1] };
        item.extend((0..entries).map(|e| at + 3 + e));
        at += 3 + entries;
        rows.push((Kind::Row(dirs.len(), steady), item));
    }
    let (mut others, mut next_other) = (FastMap::default(), 0u32);
    let (mut groups, mut list) = (FastMap::default(), Vec::new());
    for items in [&bodies, &rigid, &rows] {
        shapes(&p, &slots, items, &mut others, &widths, &mut next_other, &mut groups, &mut list);
    }
    // The other inputs, flat, in the order of first use.
    let mut order: Vec<(u32, Other)> = others.iter().map(|(&f, &at)| (at, f)).collect();
    order.sort_unstable_by_key(|&(at, _)| at);
    let mut items = Vec::new();
    for &(_, other) in &order {
        match other {
            Other::Field(f) => {
                let ident = &fields[f].ident;
                match widths[f] {
                    1 => items.push(format!("s.{ident}")),
                    w => items.extend((0..w).map(|c| format!("s.{ident}[{c}]"))),
                }
            }
            // `f64`'s method of the function's name, as the row-by-row module calls it.
            Other::Call(func, f, c) => {
                let ident = &fields[f].ident;
                let x = if widths[f] == 1 { format!("s.{ident}") } else { format!("s.{ident}[{c}]") };
                items.push(format!("{x}.{}()", func.name()));
            }
        }
    }
    let _ = writeln!(
        out,
        "/// The inputs the shapes read besides positions and velocities (parameters, time, angles, and the\n\
         /// one-argument functions of them the rows call, such as a rigid body's sin θ and cos θ), flat.\n\
         fn others(s: &State) -> [f64; {}] {{\n    {}{}\n}}\n",
        items.len(),
        if items.is_empty() { "let _ = s;\n    " } else { "" },
        array(&items)
    );
    for (id, shape) in list.iter().enumerate() {
        shape_fn(out, ctx, id, shape, formulas, system, g)?;
    }
    // `prepare`: the bodies' shapes, then the rows'. Where no row reads the velocities, the
    // velocities the rows were evaluated at (`ev`) are not kept; where the bodies' items
    // cannot change with the positions, `prepare_moved` (the rows after a substep's drift)
    // leaves them out, and `prepare` is the bodies, then `prepare_moved`.
    let split = step.still && !step.velocities;
    let prelude = if arrays {
        "    let (q, v) = (&s.position, &s.velocity);\n    let x = others(s);"
    } else {
        "    let (q, v) = (&positions(s), &velocities(s));\n    let x = others(s);"
    };
    let _ = writeln!(
        out,
        "/// The rows at the state, flattened for the step into `p` (nothing allocated): each shape's function over its instances.\n\
         fn prepare(s: &State, p: &mut Prepared<DIM>) {{\n{prelude}"
    );
    if step.velocities {
        let _ = writeln!(out, "    let mut ev = [[0.0; DIM]; SLOTS];");
    }
    let ev = |x: String| if step.velocities { x } else { String::new() };
    let mut moved = !split;
    // Whether `finish` is left for some row (its C reads the time, or its shape's instances
    // keep their entries in different orders).
    let mut finish = false;
    // The shapes whose rows' m_eff = 1/m is taken in a pass of its own (`Prepared::invert_mass`):
    // where J takes a division or a root, so that the next rows' divisions need not wait on it.
    let mut deferred = Vec::new();
    // A shape whose rows are all `UNIT` and read no time takes each row's m_eff from
    // `unit_mass` (`Prepared::unit_row`), which `prepare` fills from the bodies' 1/m before
    // the first row's shape (in `prepare`, not `prepare_moved`, where the bodies stay).
    let unit = |shape: &Shape| {
        matches!(shape.kind, Kind::Row(_, true)) && shape.items.iter().all(|&i| step.pattern.is_unit(i))
    };
    let mut masses = list.iter().any(unit);
    for (id, shape) in list.iter().enumerate() {
        if masses && shape.kind.is_row() {
            masses = false;
            let _ = writeln!(out, "    p.unit_masses();");
        }
        if !moved && (shape.kind.is_row() || id + 1 == list.len()) {
            moved = true;
            let _ = writeln!(
                out,
                "    let _ = (q, v, &x);\n    prepare_moved(s, p);\n}}\n\n\
                 /// The rows after the positions moved within a step: the rows' shapes (the bodies' 1/m and F read neither\n\
                 /// positions, velocities nor the time).\n\
                 fn prepare_moved(s: &State, p: &mut Prepared<DIM>) {{\n{prelude}"
            );
        }
        let w = shape.bodies + shape.others;
        if w == 0 {
            let _ = writeln!(out, "    for &i in SHAPE_{id}_ITEMS.iter() {{");
            let _ = writeln!(out, "        let (o, i) = (shape_{id}(q, v, &x, &[]), i as usize);");
        } else {
            let _ = writeln!(
                out,
                "    for (&i, t) in SHAPE_{id}_ITEMS.iter().zip(SHAPE_{id}_TABLE.as_chunks::<{w}>().0) {{"
            );
            let _ = writeln!(out, "        let (o, i) = (shape_{id}(q, v, &x, t), i as usize);");
        }
        let comps = |from: usize| array(&(from..from + dim).map(|c| format!("o[{c}]")).collect::<Vec<_>>());
        let list = |from: usize, count: usize| (from..from + count).map(|c| format!("o[{c}]")).collect::<Vec<_>>();
        match shape.kind {
            Kind::Body => {
                let _ = writeln!(out, "        p.inverse_mass[i] = 1.0 / o[0];");
                let _ = write!(out, "{}", ev(format!("        ev[i] = {};\n", comps(1))));
                let _ = writeln!(out, "        p.force[i] = {};", comps(1 + dim));
            }
            Kind::Rigid if three => {
                // The body's three axis slots from its I, ω, τ and axes (`Prepared::axis_slots`).
                let axes: Vec<String> = (0..3).map(|a| array(&list(9 + 3 * a, 3))).collect();
                let _ = writeln!(
                    out,
                    "        p.axis_slots(&mut ev, BODIES + 3 * i, {}, {}, {}, {});",
                    array(&list(0, 3)),
                    array(&list(3, 3)),
                    array(&list(6, 3)),
                    array(&axes)
                );
            }
            Kind::Rigid => {
                let _ = writeln!(out, "        p.inverse_mass[BODIES + i] = 1.0 / o[0];");
                let _ = write!(out, "{}", ev("        ev[BODIES + i] = [o[1], 0.0];\n".to_string()));
                let _ = writeln!(out, "        p.force[BODIES + i] = [o[2], 0.0];");
            }
            Kind::Row(linear, steady) => {
                // C/κ, Ċ/κ (into `time_rate`, which `finish` turns into ∂C/∂t) and J: a pass of
                // its own, so the divisions of one row's m_eff do not wait on its J's. Jʷ after
                // the linear entries: 2D one number per slot, 3D the world vector, projected
                // on the slot's axis (`prepare` of the row-by-row module).
                let width = if three { 3 } else { 1 };
                let base = if steady { 1 } else { 2 };
                let angular = (shape.outputs.len() - base - linear * dim) / width;
                let entries = linear + angular;
                let _ = writeln!(out, "        let e = ROW_START[i];");
                // x·1 = x exactly: where every instance's 1/κ is 1, no product (and no load of
                // it by the row's index, which the compiler cannot fold).
                let scaled: fn(&str) -> String = if shape.items.iter().all(|&i| inverse_scales[i] == 1.0) {
                    |x: &str| x.to_string()
                } else {
                    |x: &str| format!("{x} * INVERSE_SCALE[i]")
                };
                let _ = writeln!(out, "        p.value[i] = {};", scaled("o[0]"));
                if !steady {
                    let _ = writeln!(out, "        p.time_rate[i] = {};", scaled("o[1]"));
                }
                // Each entry's place in its row in the step's order, when every instance has
                // the same: a row whose C reads no time then gets its m_eff in this pass, from
                // its entries as evaluated (`Prepared::steady_row`), not in `finish`.
                let place = |i: usize| (0..entries).map(|x| entry_at[starts[i] + x] - starts[i]).collect::<Vec<_>>();
                let first = shape.items.first().map(|&i| place(i));
                let common = first.filter(|p| shape.items.iter().all(|&i| place(i) == *p));
                let fused = common.filter(|_| steady);
                finish |= fused.is_none();
                let mut row = vec![String::new(); entries];
                for e in 0..entries {
                    let at = match &fused {
                        Some(place) if place[e] == 0 => "e".to_string(),
                        Some(place) => format!("e + {}", place[e]),
                        None if e == 0 => "e".to_string(),
                        None => format!("e + {e}"),
                    };
                    let at = if in_order || fused.is_some() { at } else { format!("ENTRY_AT[{at}]") };
                    let value = if e < linear {
                        comps(base + e * dim)
                    } else if three {
                        let from = base + linear * dim + (e - linear) * 3;
                        format!("[dot3(&p.axes[ROW_BODY[{at}]], &{}), 0.0, 0.0]", array(&list(from, 3)))
                    } else {
                        format!("[o[{}], 0.0]", base + linear * dim + (e - linear))
                    };
                    match &fused {
                        Some(place) => row[place[e]] = value,
                        None => {
                            let _ = writeln!(out, "        p.jacobian[{at}] = {value};");
                        }
                    }
                }
                if fused.is_some() && unit(shape) {
                    let _ = writeln!(out, "        p.effective_mass[i] = p.unit_row(i, e, {});", array(&row));
                } else if fused.is_some() {
                    let divides = shape.ops.iter().any(|op| {
                        matches!(op, Op::Div(..) | Op::Powf(..) | Op::Call(..) | Op::Norm2(..) | Op::Norm3(..))
                    });
                    let m = format!("p.steady_row(i, e, {})", array(&row));
                    if divides {
                        deferred.push(id);
                        let _ = writeln!(out, "        p.effective_mass[i] = {m};");
                    } else {
                        let _ = writeln!(out, "        p.effective_mass[i] = effective_mass({m});");
                    }
                }
            }
        }
        let _ = writeln!(out, "    }}");
    }
    if finish {
        let _ = writeln!(out, "    p.finish({});", if step.velocities { "&ev" } else { "&[]" });
    } else {
        for id in &deferred {
            let _ =
                writeln!(out, "    for &i in SHAPE_{id}_ITEMS.iter() {{\n        p.invert_mass(i as usize);\n    }}");
        }
        if step.velocities {
            let _ = writeln!(out, "    let _ = &ev;");
        }
    }
    if three {
        // The body-frame ω the gyroscopic terms were taken at, for the kick.
        let _ = writeln!(out, "    p.velocity = ev;\n    p.first = first_angular(&p.axes);");
    }
    let _ = writeln!(out, "}}\n");
    if !split {
        let _ = writeln!(
            out,
            "/// The rows after the positions moved within a step: all of `prepare`.\n\
             #[inline(always)]\n\
             fn prepare_moved(s: &State, p: &mut Prepared<DIM>) {{\n    prepare(s, p);\n}}\n"
        );
    }
    step_accessors(out, places, step);
    Ok(())
}

/// One shape's function and tables.
fn shape_fn(
    out: &mut String,
    ctx: &Ctx<'_>,
    id: usize,
    shape: &Shape,
    formulas: &Formulas,
    system: &System,
    g: &Graph,
) -> Result<(), GenerateError> {
    let nb = shape.bodies;
    let texts: Vec<String> = shape
        .sources
        .iter()
        .map(|s| match *s {
            Source::Position(b, c) => format!("q[t[{b}] as usize][{c}]"),
            Source::Velocity(b, c) => format!("v[t[{b}] as usize][{c}]"),
            Source::Other(o, 0) => format!("x[t[{}] as usize]", nb + o as usize),
            Source::Other(o, c) => format!("x[t[{}] as usize + {c}]", nb + o as usize),
        })
        .collect();
    let program = Program {
        ops: shape.ops.clone(),
        n_inputs: shape.sources.len(),
        input_ranges: Vec::new(),
        outputs: shape.outputs.clone(),
        output_ranges: (0..shape.outputs.len()).map(|i| i..i + 1).collect(),
    };
    let local = Ctx {
        g: ctx.g,
        inputs: ctx.inputs,
        slots: &texts,
        non_finite: Cell::new(0),
        c: false,
        room: Cell::new(ctx.room.get()),
        budget: ctx.budget,
    };
    let (lets, exprs) = local.render(&program, &vec![true; shape.outputs.len()])?;
    ctx.room.set(local.room.get());
    ctx.non_finite.set(ctx.non_finite.get() + local.non_finite.get());
    let first = shape.items[0];
    let what = if let Kind::Row(..) = shape.kind {
        format!(
            "{} row(s) like `{}`: C = {}",
            shape.items.len(),
            comment_text(&system.constraints[first].name),
            formula(g, formulas.c[first])
        )
    } else if shape.kind == Kind::Rigid {
        // The item is the rigid body's index among the rigid bodies, in file order.
        let body = system.bodies.iter().filter(|b| b.rigid.is_some()).nth(first);
        let name = body.map_or(String::new(), |b| comment_text(&b.name));
        let axes = if shape.outputs.len() > 3 { " and the principal axes" } else { "" };
        format!("{} rigid bod(ies) like `{name}`: I, ω, τ{axes}", shape.items.len())
    } else {
        format!("{} bod(ies) like `{}`: 1/m, v and F", shape.items.len(), comment_text(&system.bodies[first].name))
    };
    let reads = |f: fn(&Source) -> bool| shape.sources.iter().any(f);
    let param = |name: &str, used: bool| if used { name.to_string() } else { format!("_{name}") };
    let _ = writeln!(out, "/// Shape {id}: {what}.\n#[inline(always)]");
    let _ = writeln!(
        out,
        "fn shape_{id}({}: &[[f64; DIM]; BODIES], {}: &[[f64; DIM]; BODIES], {}: &[f64], {}: &[u32; {}]) -> [f64; {}] {{",
        param("q", reads(|s| matches!(s, Source::Position(..)))),
        param("v", reads(|s| matches!(s, Source::Velocity(..)))),
        param("x", reads(|s| matches!(s, Source::Other(..)))),
        if texts.is_empty() { "_t" } else { "t" },
        nb + shape.others,
        exprs.len()
    );
    for l in &lets {
        let _ = writeln!(out, "    {l}");
    }
    let _ = writeln!(out, "    {}\n}}", array(&exprs));
    let list = |xs: &mut dyn Iterator<Item = String>| xs.collect::<Vec<_>>().join(",");
    let _ = writeln!(
        out,
        "const SHAPE_{id}_ITEMS: [u32; {}] = [{}];",
        shape.items.len(),
        list(&mut shape.items.iter().map(|i| i.to_string()))
    );
    if nb + shape.others > 0 {
        let _ = writeln!(
            out,
            "const SHAPE_{id}_TABLE: [u32; {}] = [{}];",
            shape.table.len(),
            list(&mut shape.table.iter().map(|i| i.to_string()))
        );
    }
    let _ = writeln!(out);
    Ok(())
}
