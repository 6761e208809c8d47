//! The simplifier's work meter: a deterministic count of the term operations spent on one
//! formula, charged by the polynomial arithmetic ([`super::poly`]) as it works.
//!
//! Design note. A budget on the size of each node's canonical form alone does not bound the
//! time: one exact division (`Poly::div_exact`) of two forms far below any size limit can
//! take seconds, and a product of a thousand binomials makes a thousand products, each
//! small. So every operation that visits terms charges what it visits (a term of a sum, a
//! pair of terms of a product, weighted by the words of their coefficients) before doing it,
//! and refuses (returns `None`, as for "too large to expand") once the formula's budget is
//! spent; the simplifier then sees the meter [`exhausted`] and refuses the formula. The
//! count is a function of the input alone, never of a clock, so a refusal is reproducible.
//!
//! The meter lives in a thread-local cell rather than in an argument: the arithmetic is
//! called from many places (products, powers, common denominators, exact division inside
//! normalisation) that would otherwise all thread a budget through. It is armed only while
//! [`metered`] runs (the simplifier's outermost `canon`); outside it nothing is counted and
//! nothing is refused, so the arithmetic used elsewhere (tests, `rigid`) is unchanged.
//!
//! Not here: what a formula is (the simplifier decides when a budget starts), the error
//! (`TypeError::TooLarge`), sizes of documents and generated code (`report`, `codegen`).

use std::cell::Cell;

thread_local! {
    /// Operations still allowed in the current formula; `None` when no formula is metered.
    static LEFT: Cell<Option<u64>> = const { Cell::new(None) };
    /// Whether the current formula has asked for more than was left.
    static OVER: Cell<bool> = const { Cell::new(false) };
}

/// Runs `f` with a fresh budget of `limit` operations, unless a budget is already running
/// (a nested call spends from the outer one). Returns `f`'s result and whether the budget
/// was exhausted on the way.
pub fn metered<T>(limit: u64, f: impl FnOnce() -> T) -> (T, bool) {
    if LEFT.get().is_some() {
        let out = f();
        return (out, exhausted());
    }
    LEFT.set(Some(limit));
    OVER.set(false);
    // Disarmed however `f` ends (an early return or an unwinding panic in a test).
    struct Disarm;
    impl Drop for Disarm {
        fn drop(&mut self) {
            LEFT.set(None);
        }
    }
    let guard = Disarm;
    let out = f();
    let over = OVER.get();
    drop(guard);
    OVER.set(false);
    (out, over)
}

/// Spends `n` operations: `false` (and nothing spent) when fewer are left, which marks the
/// formula exhausted. Always `true` when no budget is running.
pub fn charge(n: u64) -> bool {
    match LEFT.get() {
        None => true,
        Some(left) if n <= left => {
            LEFT.set(Some(left - n));
            true
        }
        Some(_) => {
            LEFT.set(Some(0));
            OVER.set(true);
            false
        }
    }
}

/// Whether the running budget has been exhausted (`false` when none runs).
pub fn exhausted() -> bool {
    LEFT.get().is_some() && OVER.get()
}

/// What a word-sized coefficient costs beside its term: one operation per 64 bits.
pub fn words(bits: u64) -> u64 {
    bits / 64
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::expr::func::Func;
    use crate::expr::graph::Graph;
    use crate::expr::num::Rational;
    use crate::expr::poly::Poly;
    use std::cmp::Ordering;

    #[test]
    fn the_arithmetic_refuses_once_the_budget_is_spent() {
        let mut g = Graph::new(2);
        let (x, y) = (g.int(7), g.int(8));
        let s = Poly::atom(x).add(&Poly::atom(y)).add(&Poly::constant(Rational::int(3)));
        // (x + y + 3)^20 has 231 terms: unmetered it is computed; under a budget of 1 000
        // operations it is refused and the budget reads exhausted.
        let full = s.powi(20).expect("unmetered");
        assert_eq!(full.len(), 231);
        let (refused, over) = metered(1_000, || s.powi(20));
        assert!(refused.is_none() && over);
        // Exact division stops too: (x + y + 3)^20 / (x + y + 3) needs many steps.
        let (quotient, over) = metered(1_000, || full.div_exact(&s));
        assert!(quotient.is_none() && over);
        assert_eq!(full.div_exact(&s), s.powi(19), "unmetered, the same division succeeds");
    }

    #[test]
    fn deep_graphs_compare_without_recursion() {
        // Two towers sin(sin(…(k)…)) 200 000 deep that differ only at the bottom: the
        // comparison walks the whole depth on a heap stack, on a thread whose 256 KiB
        // stack a recursion of that depth would overflow.
        let worker = std::thread::Builder::new().stack_size(256 << 10).spawn(|| {
            let mut g = Graph::new(2);
            let (mut a, mut b) = (g.int(1), g.int(2));
            for _ in 0..200_000 {
                a = g.call(Func::Sin, &[a]).expect("scalar");
                b = g.call(Func::Sin, &[b]).expect("scalar");
            }
            (g.cmp_nodes(a, b), g.cmp_nodes(b, a), g.cmp_nodes(a, a))
        });
        let orders = worker.expect("thread").join().expect("no overflow");
        assert_eq!(orders, (Ordering::Less, Ordering::Greater, Ordering::Equal));
    }

    #[test]
    fn a_budget_refuses_past_its_limit_and_only_while_it_runs() {
        assert!(charge(u64::MAX), "nothing is counted outside a budget");
        let ((), over) = metered(10, || {
            assert!(charge(4) && charge(6));
            assert!(!charge(1));
            assert!(exhausted());
            // A nested budget spends from the outer one.
            let ((), inner) = metered(1_000, || assert!(!charge(1)));
            assert!(inner);
        });
        assert!(over);
        assert!(!exhausted() && charge(u64::MAX));
        let ((), over) = metered(10, || assert!(charge(10)));
        assert!(!over, "a fresh budget each time");
    }
}
