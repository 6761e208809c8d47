use lagrange::derive::derive;
use lagrange::expr::Ty;
use lagrange::expr::print::{Style, print};
use lagrange::model::system::{BodySpec, MassSpec, SystemBuilder};

#[test]
fn bead() {
    for dim in [2, 3] {
        let mut b = SystemBuilder::new("bead", dim).unwrap();
        b.parameter("l", Ty::Scalar).unwrap();
        b.body(&BodySpec {
            name: "bead",
            position: "r",
            velocity: "v",
            acceleration: "a",
            force: "F",
            mass: MassSpec::Symbol("m"),
        })
        .unwrap();
        b.constraint("wire", "dot(r,r) = l^2").unwrap();
        let mut s = b.finish();
        let d = derive(&mut s).unwrap();
        let g = &s.graph;
        let dc = &d.constraints[0];
        for (label, id) in [
            ("C", dc.c),
            ("Cdot raw", dc.c_dot_raw),
            ("Cdot", dc.c_dot),
            ("Cddot raw", dc.c_ddot_raw),
            ("Cddot", dc.c_ddot),
            ("J", dc.direction[0].1),
            ("c", dc.c_term),
            ("A", d.a[0].2),
            ("b", d.b[0]),
            ("lambda", d.lambda.unwrap()),
            ("force", d.forces.as_ref().unwrap()[0].1),
        ] {
            println!(
                "{label:10} {}    |    {}   |   {}",
                print(g, id, Style::Text).unwrap(),
                print(g, id, Style::Source).unwrap(),
                print(g, id, Style::Latex).unwrap()
            );
        }
    }
}

#[test]
fn rod_and_pendulum() {
    let mut b = SystemBuilder::new("rod", 2).unwrap();
    b.parameter("l", Ty::Scalar).unwrap();
    b.parameter("l2", Ty::Scalar).unwrap();
    b.body(&BodySpec {
        name: "p1",
        position: "r1",
        velocity: "v1",
        acceleration: "a1",
        force: "F1",
        mass: MassSpec::Symbol("m1"),
    })
    .unwrap();
    b.body(&BodySpec {
        name: "p2",
        position: "r2",
        velocity: "v2",
        acceleration: "a2",
        force: "F2",
        mass: MassSpec::Symbol("m2"),
    })
    .unwrap();
    b.constraint("rod", "dot(r1 - r2, r1 - r2) = l^2").unwrap();
    let mut s = b.finish();
    let d = derive(&mut s).unwrap();
    let g = &s.graph;
    let dc = &d.constraints[0];
    for (label, id) in [
        ("C", dc.c),
        ("Cdot raw", dc.c_dot_raw),
        ("Cdot", dc.c_dot),
        ("Cddot", dc.c_ddot),
        ("J1", dc.direction[0].1),
        ("J2", dc.direction[1].1),
        ("c", dc.c_term),
        ("A", d.a[0].2),
        ("b", d.b[0]),
        ("lambda", d.lambda.unwrap()),
        ("force1", d.forces.as_ref().unwrap()[0].1),
        ("force2", d.forces.as_ref().unwrap()[1].1),
    ] {
        println!("{label:10} {}    |    {}", print(g, id, Style::Text).unwrap(), print(g, id, Style::Source).unwrap());
    }
}
