//! Parse + validate + derive (with simplification) per constraint file, with divan.
//!
//! `cargo bench --bench derive`. Cases: the article's bead in 2D and 3D, from its file
//! (`bead`) and from its declarations with the constraint parsed from its text
//! (`bead_expressions`, the work the reference tools of issue 2 were timed on), and an
//! N-link chain (N = 10, 50, 200, 1000) from its file, with A and b for every link. Each
//! file case has its
//! baseline in the same run: `load` alone (parsing, type checking, building the graph), so
//! the cost of the derivation itself is the difference. The `*_text` cases add what
//! `lagrange derive FILE` does after that: the text document (`report::derivation`), so the
//! whole command is measured too, file reading and stdout aside. `rope_text`: a rope over
//! pulleys through k = 1…8 segments (sums of norms), whose C̈ is linear in k (asserted).
//! `revolute`: the 2D revolute joint between two rigid bodies beside the bead, and `hinge_3d`
//! the 3D hinge (`constraints/joints/hinge_3d.toml`);
//! `rigid_chain_links`: N rigid rods on revolute joints (N = 10, 100, 1000), each next to its
//! load-only baseline. Targets (issue 2): bead
//! < 20 µs; chain linear in N, N = 200 < 4 ms, N = 1000 < 20 ms.

/// The same allocator as the `lagrange` binary (mimalloc: a symbolic derivation allocates
/// many small forms).
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

use divan::{Bencher, black_box};
use lagrange::derive::{Options, derive, derive_with};
use lagrange::expr::Ty;
use lagrange::expr::print::{Style, print};
use lagrange::model::file::load;
use lagrange::model::system::{BodySpec, MassSpec, SystemBuilder};
use lagrange::report::derivation::{Format, document};
use lagrange::scenario::chain;

fn main() {
    divan::main();
}

const BEAD_2D: &str = include_str!("../constraints/bead_on_wire.toml");
const BEAD_3D: &str = include_str!("../constraints/bead_on_sphere.toml");
const REVOLUTE: &str = include_str!("../constraints/joints/revolute.toml");
const HINGE_3D: &str = include_str!("../constraints/joints/hinge_3d.toml");

fn load_and_derive(text: &str) -> usize {
    let loaded = load(text).expect("the file loads");
    let d = derive(&loaded.system).expect("the file derives");
    d.a.len() + d.b.len()
}

/// What `lagrange derive FILE` does for the text output: load, derive, lay out.
fn load_derive_and_print(text: &str) -> usize {
    let loaded = load(text).expect("the file loads");
    let d = derive_with(&loaded.system, Options { document: true, steps: false }).expect("the file derives");
    document(&loaded.system, &d, Format::Text, false).expect("the document builds").len()
}

#[divan::bench(args = [2, 3])]
fn bead(bencher: Bencher, dim: usize) {
    let text = if dim == 2 { BEAD_2D } else { BEAD_3D };
    bencher.bench(|| load_and_derive(black_box(text)));
}

/// Parse + derive + simplify of the bead from its declarations, without a file: the symbols
/// declared, the constraint parsed from its text `dot(r,r) = l^2`, derived, simplified. This
/// is the work SymPy, SymEngine and CasADi were timed on in issue 2; `bead` adds reading the
/// TOML file (and checking its `[[expect]]` formulas and `[scene]`).
#[divan::bench(args = [2, 3])]
fn bead_expressions(bencher: Bencher, dim: usize) {
    // What is timed ends at the article's form (checked once, outside the timing).
    let system = bead_from_declarations(dim);
    let d = derive(&system).expect("the bead derives");
    let g = &d.graph;
    let lambda = print(g, d.lambda.expect("λ in closed form"), Style::Source).expect("prints");
    assert_eq!(lambda, "-(m*dot(v, v) + dot(F, r))/dot(r, r)");
    let force = print(g, d.forces.as_ref().expect("the force")[0].1, Style::Source).expect("prints");
    assert_eq!(force, "-(m*dot(v, v) + dot(F, r))/dot(r, r)*r");
    bencher.bench(|| {
        let system = bead_from_declarations(black_box(dim));
        let d = derive(&system).expect("the bead derives");
        d.a.len() + d.b.len()
    });
}

/// The bead declared through `SystemBuilder`: parameters `l`, `m`, the body, and its
/// constraint parsed from text.
fn bead_from_declarations(dim: usize) -> lagrange::model::system::System {
    let mut b = SystemBuilder::new("bead", dim as i64).expect("a dimension");
    b.parameter("l", Ty::Scalar).expect("a new name");
    b.parameter("m", Ty::Scalar).expect("a new name");
    let bead = BodySpec {
        name: "bead",
        position: "r",
        velocity: "v",
        acceleration: "a",
        force: "F",
        mass: MassSpec::Symbol("m"),
    };
    b.body(&bead).expect("new names");
    b.constraint("wire", black_box("dot(r,r) = l^2")).expect("a constraint");
    b.finish()
}

/// The 2D revolute joint between two rigid bodies (a vector constraint: two rows, Jᵛ and Jʷ
/// per body, the 2×2 K), beside the bead in the same run; `revolute_load_only` is its baseline.
#[divan::bench]
fn revolute(bencher: Bencher) {
    assert_eq!(load_and_derive(REVOLUTE), 5, "A has 3 entries (upper triangle), b 2");
    bencher.bench(|| load_and_derive(black_box(REVOLUTE)));
}

#[divan::bench]
fn revolute_load_only(bencher: Bencher) {
    bencher.bench(|| load(black_box(REVOLUTE)).map(|l| l.system.graph.len()).unwrap_or(0));
}

/// A 3D hinge between two rigid bodies (a ball joint's three rows and two angular rows
/// `dot(rot(q1, h1), rot(q2, b2)) = 0`; Jᵛ, the Jʷ vectors, the world inertia through the
/// body axes), beside the bead and the revolute joint in the same run; `hinge_3d_load_only`
/// is its baseline.
#[divan::bench]
fn hinge_3d(bencher: Bencher) {
    assert_eq!(load_and_derive(HINGE_3D), 20, "A has 15 entries (upper triangle of 5 rows), b 5");
    bencher.bench(|| load_and_derive(black_box(HINGE_3D)));
}

#[divan::bench]
fn hinge_3d_load_only(bencher: Bencher) {
    bencher.bench(|| load(black_box(HINGE_3D)).map(|l| l.system.graph.len()).unwrap_or(0));
}

/// An N-rod chain of rigid bodies on revolute joints, the first rod's upper end pinned at the
/// origin (`constraints/rigid/chain_20.toml`'s shape), as the constraint file's text.
fn rigid_chain(n: usize) -> String {
    let mut text = String::from(
        "title = \"rigid chain\"\ndimension = 2\n\n[parameters]\nm = 1.0\nL = 1.0\nI = 0.08\np = [0.0, 0.0]\n\n\
         [definitions]\nup = \"[-L/2, 0]\"\ndown = \"[L/2, 0]\"\n",
    );
    for i in 1..=n {
        text += &format!(
            "\n[[bodies]]\nname = \"rod{i}\"\nposition = \"x{i}\"\nvelocity = \"v{i}\"\nacceleration = \"a{i}\"\n\
             mass = \"m\"\nforce = \"F{i}\"\norientation = \"th{i}\"\nangular_velocity = \"w{i}\"\n\
             angular_acceleration = \"alpha{i}\"\ninertia = \"I\"\ntorque = \"T{i}\"\n"
        );
    }
    text += "\n[[constraints]]\nname = \"pin\"\nexpr = \"x1 + rot(th1, up) = p\"\n";
    for i in 1..n {
        text += &format!(
            "\n[[constraints]]\nname = \"joint{i}\"\nexpr = \"x{i} + rot(th{i}, down) = x{j} + rot(th{j}, up)\"\n",
            j = i + 1
        );
    }
    text
}

/// The rigid chain of N = 10, 100, 1000 rods (2N rows): derived in time linear in N, as the
/// point-mass chains are (A has at most 3 (upper-triangle) entries a row: the band of a chain).
#[divan::bench(args = [10, 100, 1000], sample_count = 5)]
fn rigid_chain_links(bencher: Bencher, n: usize) {
    let text = rigid_chain(n);
    assert!(load_and_derive(&text) <= 5 * 2 * n);
    bencher.bench(|| load_and_derive(black_box(&text)));
}

#[divan::bench(args = [10, 100, 1000], sample_count = 5)]
fn rigid_chain_load_only(bencher: Bencher, n: usize) {
    let text = rigid_chain(n);
    bencher.bench(|| load(black_box(&text)).map(|l| l.system.graph.len()).unwrap_or(0));
}

#[divan::bench(args = [2, 3])]
fn bead_load_only(bencher: Bencher, dim: usize) {
    let text = if dim == 2 { BEAD_2D } else { BEAD_3D };
    bencher.bench(|| load(black_box(text)).map(|l| l.system.graph.len()).unwrap_or(0));
}

/// Two bodies and a radical over a time-dependent rational function: its C̈ is large, and
/// reducing `sqrt(x)²` in it once took 40 s (now well under a second).
#[divan::bench(sample_count = 5)]
fn radical_of_rational(bencher: Bencher) {
    let text = format!(
        "dimension = 2\n[parameters]\nk = 1.0\n{}{}[[constraints]]\nname = \"c\"\n\
         expr = \"sqrt(1 + (dot(r1/(1 + t^2), r2 + r1))^2) + k*dot(r1, r2)\"\n",
        "[[bodies]]\nname = \"p1\"\nposition = \"r1\"\nvelocity = \"v1\"\nacceleration = \"a1\"\nmass = \"m1\"\nforce = \"F1\"\n",
        "[[bodies]]\nname = \"p2\"\nposition = \"r2\"\nvelocity = \"v2\"\nacceleration = \"a2\"\nmass = \"m2\"\nforce = \"F2\"\n",
    );
    bencher.bench(|| load_and_derive(black_box(&text)));
}

#[divan::bench(args = [10, 50, 200, 1000], sample_count = 20)]
fn chain_links(bencher: Bencher, n: usize) {
    let text = chain(n);
    // A is tridiagonal: n diagonal and n − 1 off-diagonal entries, and n entries of b.
    assert_eq!(load_and_derive(&text), 3 * n - 1);
    bencher.bench(|| load_and_derive(black_box(&text)));
}

#[divan::bench(args = [10, 50, 200, 1000], sample_count = 20)]
fn chain_load_only(bencher: Bencher, n: usize) {
    let text = chain(n);
    bencher.bench(|| load(black_box(&text)).map(|l| l.system.graph.len()).unwrap_or(0));
}

#[divan::bench(args = [2, 3])]
fn bead_text(bencher: Bencher, dim: usize) {
    let text = if dim == 2 { BEAD_2D } else { BEAD_3D };
    bencher.bench(|| load_derive_and_print(black_box(text)));
}

#[divan::bench(args = [10, 50, 200, 1000], sample_count = 20)]
fn chain_text(bencher: Bencher, n: usize) {
    let text = chain(n);
    bencher.bench(|| load_derive_and_print(black_box(&text)));
}

/// A rope over pulleys through `k` segments, `norm(r1 - p1) + norm(r2 - p1) + norm(r2 - p2)
/// + …  = L` (2D, the bodies and pulleys alternating), as the constraint file's text.
fn rope(k: usize) -> String {
    let body = |s: usize| s / 2 + 1 + s % 2;
    let pulley = |s: usize| s.div_ceil(2) + usize::from(s.is_multiple_of(2));
    let bodies = body(k - 1).max(1);
    let mut text = String::from("title = \"rope\"\ndimension = 2\n\n[parameters]\nL = 10.0\n");
    for p in 1..=pulley(k - 1) {
        text += &format!("p{p} = [{p}.0, 0.0]\n");
    }
    for b in 1..=bodies {
        text += &format!("m{b} = 1.0\n");
    }
    for b in 1..=bodies {
        text += &format!(
            "\n[[bodies]]\nname = \"b{b}\"\nposition = \"r{b}\"\nvelocity = \"v{b}\"\nacceleration = \"a{b}\"\nmass = \"m{b}\"\nforce = \"F{b}\"\n"
        );
    }
    let terms: Vec<String> = (0..k).map(|s| format!("norm(r{} - p{})", body(s), pulley(s))).collect();
    text + &format!("\n[[constraints]]\nname = \"rope\"\nexpr = \"{} = L\"\n", terms.join(" + "))
}

/// The rope through k = 1…8 segments: load, derive and the text document. Its C̈ is a sum
/// of k terms `(v·v + d·a)/|d| − (d·v)²/|d|³`, so its size is linear in k (checked here:
/// at most 100 characters a segment in the expression language).
#[divan::bench(args = [1, 2, 3, 4, 5, 6, 7, 8], sample_count = 10)]
fn rope_text(bencher: Bencher, k: usize) {
    let text = rope(k);
    let loaded = load(&text).expect("the rope loads");
    let d = derive(&loaded.system).expect("the rope derives");
    let c_ddot = print(&d.graph, d.constraints[0].c_ddot, Style::Source).expect("prints");
    assert!(c_ddot.len() <= 100 * k, "C̈ of {k} segments is {} characters", c_ddot.len());
    bencher.bench(|| load_derive_and_print(black_box(&text)));
}
