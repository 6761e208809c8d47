//! A tape compiled to machine code at load (the `jit` feature): [`Tape::jit`] gives a
//! [`JitTape`], whose [`eval`](JitTape::eval) computes what [`Tape::eval`] computes, bit for
//! bit, without the interpreter's dispatch.
//!
//! Each instruction of the tape's batched code becomes the same IEEE operations in
//! Cranelift's IR, in the same order on the same operands — an addition is an addition, a
//! fused `a·b + c·d` is two products and a sum, never an FMA — and Cranelift neither
//! reassociates nor contracts floating-point arithmetic, so each result rounds as the
//! interpreter's does. What is not one IEEE operation (`powi`, `powf`, `norm`, sine, …) is a
//! call of the very Rust function the interpreter calls, through an `extern "C"` wrapper
//! below. Temporary registers become SSA values: the function is one block, inputs and
//! constants loaded from their slices where read, outputs stored at the end.
//!
//! Design note: one state per call, as [`Tape::eval`]. Compiling costs time at load (about
//! 0.1 ms for a small tape, some 10 µs an instruction for a big one: `docs/speed.md`) and the feature
//! costs Cranelift's build, so it is off by default; callers keep the interpreter as the
//! fallback for a host Cranelift does not support ([`JitError::Host`]).
//!
//! Not here: batches of states; the callers (`numeric::rows`' `RowProgram::compile`, which
//! a simulation asks for through `simulate::Compile`).

use super::program::{norm2, norm3};
use super::tape::{Code, Tape};
use crate::expr::Func;
use crate::expr::eval;
use cranelift_codegen::ir::{AbiParam, InstBuilder, MemFlagsData, Signature, Value, types};
use cranelift_codegen::settings::{self, Configurable};
use cranelift_frontend::{FunctionBuilder, FunctionBuilderContext};
use cranelift_jit::{JITBuilder, JITModule};
use cranelift_module::Module;
use std::sync::Mutex;

/// Why a tape could not be compiled to machine code. The caller keeps the interpreter.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum JitError {
    /// Cranelift has no code generator for this processor or system.
    #[error("this host cannot compile tapes to machine code ({0}): use `Tape::eval`")]
    Host(String),
    /// Cranelift refused the function or could not map its code.
    #[error("the tape could not be compiled to machine code: {0}")]
    Codegen(String),
    /// The tape reads a register no instruction wrote (tapes from `Tape::compile` never do).
    #[error("the tape reads register {0} before writing it")]
    Malformed(u32),
    /// A slot lies past the 2 GiB a load's offset reaches (a tape of 2²⁸ inputs).
    #[error("slot {0} lies past a load's 32-bit offset: use `Tape::eval`")]
    Offset(usize),
    /// The tape holds too many values at once for the compiled code's stack frame.
    #[error("the tape holds {0} temporaries at once, more than compiled code keeps on a stack: use `Tape::eval`")]
    TooLarge(usize),
}

/// The compiled function: inputs, constants, outputs.
type Entry = unsafe extern "C" fn(*const f64, *const f64, *mut f64);

/// The most temporaries a compiled tape may hold at once (8 bytes each on the stack at
/// worst: 256 KiB), so its frame fits a thread's stack; a bigger tape is refused.
const MAX_TEMPORARIES: usize = 1 << 15;

/// A tape compiled to machine code: [`eval`](JitTape::eval) gives [`Tape::eval`]'s results,
/// bit for bit. Its code is freed when it is dropped.
///
/// `Send` and `Sync` without an `unsafe impl`: the code is immutable and touches only its
/// arguments and its own frame, so threads may run it at once; the module that owns it
/// (`Send`, not `Sync`) sits behind a mutex that only `drop` reaches.
pub struct JitTape {
    entry: Entry,
    /// The tape's constants, read by the code where used (as inputs are).
    consts: Box<[f64]>,
    n_inputs: usize,
    n_outputs: usize,
    /// Owns the code `entry` points into; touched only by `drop`. The mutex makes the
    /// module (`Send`, not `Sync`) shareable; `eval` never locks it.
    module: Mutex<Option<JITModule>>,
}

impl std::fmt::Debug for JitTape {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("JitTape").field("n_inputs", &self.n_inputs).field("n_outputs", &self.n_outputs).finish()
    }
}

impl Drop for JitTape {
    fn drop(&mut self) {
        let module = self.module.get_mut().unwrap_or_else(std::sync::PoisonError::into_inner).take();
        if let Some(module) = module {
            // SAFETY: `entry` is the only pointer into the module's code; it is called only by
            // `eval`, which borrows `self`, so no call runs now (`drop` has `self` exclusively)
            // and none can run after.
            unsafe { module.free_memory() };
        }
    }
}

impl JitTape {
    /// Evaluates every root at one state: [`Tape::eval`]'s contract and results.
    ///
    /// # Panics
    /// If `inputs` is not [`input_len`](JitTape::input_len) long or `outputs` not
    /// [`output_len`](JitTape::output_len) long.
    #[inline]
    pub fn eval(&self, inputs: &[f64], outputs: &mut [f64]) {
        if inputs.len() != self.n_inputs || outputs.len() != self.n_outputs {
            self.misuse(inputs.len(), outputs.len());
        }
        // SAFETY: the lengths are checked above. The code reads `inputs` only at offsets of
        // input slots (below `n_inputs`) and `consts` below its length, writes `outputs`
        // only at offsets of output components (below `n_outputs`), touches no other memory
        // but its own stack frame (at most `MAX_TEMPORARIES` spilled values, probed inline,
        // so an overflow meets the guard page as Rust's own frames do), and calls only the
        // wrappers below (safe Rust that neither panics nor unwinds). It lives as long as
        // `self` (`drop` frees it).
        unsafe { (self.entry)(inputs.as_ptr(), self.consts.as_ptr(), outputs.as_mut_ptr()) }
    }

    /// Number of input slots (the tape's).
    pub fn input_len(&self) -> usize {
        self.n_inputs
    }

    /// Number of output components (the tape's).
    pub fn output_len(&self) -> usize {
        self.n_outputs
    }

    /// The panic of a call of [`eval`](JitTape::eval) with slices of the wrong lengths: out
    /// of line, as [`Tape::eval`]'s.
    #[cold]
    #[inline(never)]
    fn misuse(&self, inputs: usize, outputs: usize) -> ! {
        assert_eq!(inputs, self.n_inputs, "input length");
        assert_eq!(outputs, self.n_outputs, "output length");
        unreachable!("eval called with the right lengths")
    }
}

impl Tape {
    /// Compiles the tape to machine code for this processor (Cranelift).
    ///
    /// Fails, rather than panicking, on a host Cranelift does not support
    /// ([`JitError::Host`]) and for a tape holding more than 32 768 values at once
    /// ([`JitError::TooLarge`]: its frame would not fit a thread's stack): keep the tape and
    /// call [`Tape::eval`] then.
    ///
    /// ```
    /// # use lagrange::model::file::load;
    /// # use lagrange::numeric::tape::Tape;
    /// let mut loaded = load("dimension = 2\n[parameters]\nl = 1.0\n[[bodies]]\nname = \"b\"\n\
    ///     position = \"r\"\nvelocity = \"v\"\nacceleration = \"a\"\nmass = 1.0\nforce = \"F\"\n\
    ///     [[constraints]]\nname = \"c\"\nexpr = \"dot(r, r) = l^2\"").unwrap();
    /// let s = &mut loaded.system;
    /// let c = s.constraints[0].c;
    /// let (r, l) = (s.bodies[0].position, s.graph.symbol_named("l").unwrap());
    /// let tape = Tape::compile(&s.graph, &[c], &[r, l]).unwrap();
    /// let (mut out, mut want) = ([0.0], [0.0]);
    /// tape.eval(&[3.0, 4.0, 2.0], &mut tape.scratch(), &mut want);
    /// match tape.jit() {
    ///     Ok(jit) => jit.eval(&[3.0, 4.0, 2.0], &mut out),
    ///     Err(_) => out = want, // a host without a code generator
    /// }
    /// assert_eq!(out[0].to_bits(), want[0].to_bits());
    /// ```
    pub fn jit(&self) -> Result<JitTape, JitError> {
        let mut flags = settings::builder();
        let codegen = |e: &dyn std::fmt::Display| JitError::Codegen(e.to_string());
        for (name, value) in [
            ("opt_level", "speed"),
            // cranelift-jit's requirements: absolute addresses, no colocated libcalls.
            ("is_pic", "false"),
            ("use_colocated_libcalls", "false"),
            // A big tape spills to a big frame: probe it, as Rust's own frames are.
            ("enable_probestack", "true"),
            ("probestack_strategy", "inline"),
            // Inputs and constants are loaded where read, not merged into one load whose
            // value would live (spilled) from its first reader to its last: the frame then
            // holds at most the tape's own temporaries.
            ("enable_alias_analysis", "false"),
            ("enable_verifier", if cfg!(debug_assertions) { "true" } else { "false" }),
        ] {
            flags.set(name, value).map_err(|e| codegen(&e))?;
        }
        let isa = cranelift_native::builder()
            .map_err(|e| JitError::Host(e.to_string()))?
            .finish(settings::Flags::new(flags))
            .map_err(|e| codegen(&e))?;
        let temporaries = self.jit_registers() - self.input_len() - self.jit_consts().len();
        if temporaries > MAX_TEMPORARIES {
            return Err(JitError::TooLarge(temporaries));
        }
        let mut module = JITModule::new(JITBuilder::with_isa(isa, cranelift_module::default_libcall_names()));
        let entry = match self.define(&mut module) {
            Ok(entry) => entry,
            Err(e) => {
                // SAFETY: no pointer into the module's code was taken (or escapes).
                unsafe { module.free_memory() };
                return Err(e);
            }
        };
        Ok(JitTape {
            entry,
            consts: self.jit_consts().into(),
            n_inputs: self.input_len(),
            n_outputs: self.output_len(),
            module: Mutex::new(Some(module)),
        })
    }

    /// Defines the tape's function in `module` and finalizes it.
    fn define(&self, module: &mut JITModule) -> Result<Entry, JitError> {
        let codegen = |e: &dyn std::fmt::Display| JitError::Codegen(e.to_string());
        let ptr = module.target_config().pointer_type();
        let call_conv = module.target_config().default_call_conv;
        let mut sig = module.make_signature();
        sig.params.extend([AbiParam::new(ptr), AbiParam::new(ptr), AbiParam::new(ptr)]);
        let id = module.declare_anonymous_function(&sig).map_err(|e| codegen(&e))?;
        let mut ctx = module.make_context();
        ctx.func.signature = sig;
        let mut fctx = FunctionBuilderContext::new();
        let mut b = FunctionBuilder::new(&mut ctx.func, &mut fctx);
        let block = b.create_block();
        b.append_block_params_for_function_params(block);
        b.switch_to_block(block);
        b.seal_block(block);
        let [inputs, consts_at, outputs] = [0, 1, 2].map(|k| b.block_params(block)[k]);
        // The wrappers' signatures: f(f64, f64) → f64, powi(f64, i32) → f64, norm3(f64³) → f64.
        let sig_of = |params: &[types::Type]| {
            let mut s = Signature::new(call_conv);
            s.params.extend(params.iter().map(|&t| AbiParam::new(t)));
            s.returns.push(AbiParam::new(types::F64));
            s
        };
        let binary = b.import_signature(sig_of(&[types::F64, types::F64]));
        let powi = b.import_signature(sig_of(&[types::F64, types::I32]));
        let ternary = b.import_signature(sig_of(&[types::F64, types::F64, types::F64]));
        // Inputs, constants and outputs are aligned `f64` slices, valid for the call.
        let mem = MemFlagsData::trusted();
        let (n_inputs, consts) = (self.input_len(), self.jit_consts());
        // The value each temporary register holds now (registers are reused: a later write
        // replaces it). Inputs and constants are loaded at each read: an SSA value kept from
        // the first read to the last would lengthen its life (a big tape's frame) for a load
        // that costs what a reload from the frame would.
        let mut regs: Vec<Option<Value>> = vec![None; self.jit_registers()];
        let offset = |k: usize| i32::try_from(8 * k).map_err(|_| JitError::Offset(k));
        let read = |b: &mut FunctionBuilder, regs: &mut Vec<Option<Value>>, k: u32| -> Result<Value, JitError> {
            let slot = regs.get_mut(k as usize).ok_or(JitError::Malformed(k))?;
            if let Some(v) = *slot {
                return Ok(v);
            }
            let k = k as usize;
            if k < n_inputs {
                Ok(b.ins().load(types::F64, mem, inputs, offset(k)?))
            } else if k - n_inputs < consts.len() {
                Ok(b.ins().load(types::F64, mem, consts_at, offset(k - n_inputs)?))
            } else {
                Err(JitError::Malformed(k as u32))
            }
        };
        for i in self.jit_code() {
            let [a, x, c, e] = [i.a, i.b, i.c, i.e];
            let call = |b: &mut FunctionBuilder, sig, f: usize, args: &[Value]| {
                let f = b.ins().iconst(ptr, f as i64);
                let call = b.ins().call_indirect(sig, f, args);
                b.inst_results(call)[0]
            };
            let v = match i.code {
                Code::Add => {
                    let (a, x) = (read(&mut b, &mut regs, a)?, read(&mut b, &mut regs, x)?);
                    b.ins().fadd(a, x)
                }
                Code::Sub => {
                    let (a, x) = (read(&mut b, &mut regs, a)?, read(&mut b, &mut regs, x)?);
                    b.ins().fsub(a, x)
                }
                Code::Mul => {
                    let (a, x) = (read(&mut b, &mut regs, a)?, read(&mut b, &mut regs, x)?);
                    b.ins().fmul(a, x)
                }
                Code::Div => {
                    let (a, x) = (read(&mut b, &mut regs, a)?, read(&mut b, &mut regs, x)?);
                    b.ins().fdiv(a, x)
                }
                Code::Neg => {
                    let a = read(&mut b, &mut regs, a)?;
                    b.ins().fneg(a)
                }
                Code::Sq => {
                    let a = read(&mut b, &mut regs, a)?;
                    b.ins().fmul(a, a)
                }
                Code::SqAddSq => {
                    let (a, c) = (read(&mut b, &mut regs, a)?, read(&mut b, &mut regs, c)?);
                    let (p, q) = (b.ins().fmul(a, a), b.ins().fmul(c, c));
                    b.ins().fadd(p, q)
                }
                Code::MulMulAdd | Code::MulMulSub => {
                    let (a, x) = (read(&mut b, &mut regs, a)?, read(&mut b, &mut regs, x)?);
                    let (c, e) = (read(&mut b, &mut regs, c)?, read(&mut b, &mut regs, e)?);
                    let (p, q) = (b.ins().fmul(a, x), b.ins().fmul(c, e));
                    if i.code == Code::MulMulAdd { b.ins().fadd(p, q) } else { b.ins().fsub(p, q) }
                }
                Code::MulAdd | Code::MulSub => {
                    let (a, x, c) =
                        (read(&mut b, &mut regs, a)?, read(&mut b, &mut regs, x)?, read(&mut b, &mut regs, c)?);
                    let p = b.ins().fmul(a, x);
                    if i.code == Code::MulAdd { b.ins().fadd(p, c) } else { b.ins().fsub(p, c) }
                }
                Code::SubMul => {
                    let (a, x, c) =
                        (read(&mut b, &mut regs, a)?, read(&mut b, &mut regs, x)?, read(&mut b, &mut regs, c)?);
                    let p = b.ins().fmul(x, c);
                    b.ins().fsub(a, p)
                }
                Code::NegMul => {
                    let (a, x) = (read(&mut b, &mut regs, a)?, read(&mut b, &mut regs, x)?);
                    let p = b.ins().fmul(a, x);
                    b.ins().fneg(p)
                }
                Code::NegDiv => {
                    let (a, x) = (read(&mut b, &mut regs, a)?, read(&mut b, &mut regs, x)?);
                    let p = b.ins().fdiv(a, x);
                    b.ins().fneg(p)
                }
                Code::Sqrt => {
                    let a = read(&mut b, &mut regs, a)?;
                    b.ins().sqrt(a)
                }
                Code::Powi => {
                    let a = read(&mut b, &mut regs, a)?;
                    let k = b.ins().iconst(types::I32, i64::from(i.imm));
                    call(&mut b, powi, jit_powi as *const () as usize, &[a, k])
                }
                Code::Powf => {
                    let (a, x) = (read(&mut b, &mut regs, a)?, read(&mut b, &mut regs, x)?);
                    call(&mut b, binary, jit_powf as *const () as usize, &[a, x])
                }
                Code::Call(f) => {
                    let (a, x) = (read(&mut b, &mut regs, a)?, read(&mut b, &mut regs, x)?);
                    call(&mut b, binary, func(f) as *const () as usize, &[a, x])
                }
                Code::Norm2 => {
                    let (a, x) = (read(&mut b, &mut regs, a)?, read(&mut b, &mut regs, x)?);
                    call(&mut b, binary, jit_norm2 as *const () as usize, &[a, x])
                }
                Code::Norm3 => {
                    let (a, x, c) =
                        (read(&mut b, &mut regs, a)?, read(&mut b, &mut regs, x)?, read(&mut b, &mut regs, c)?);
                    call(&mut b, ternary, jit_norm3 as *const () as usize, &[a, x, c])
                }
            };
            *regs.get_mut(i.d as usize).ok_or(JitError::Malformed(i.d))? = Some(v);
        }
        for (k, &r) in self.jit_outputs().iter().enumerate() {
            let v = read(&mut b, &mut regs, r)?;
            b.ins().store(mem, v, outputs, offset(k)?);
        }
        b.ins().return_(&[]);
        b.finalize(module.target_config());
        module.define_function(id, &mut ctx).map_err(|e| codegen(&e))?;
        module.clear_context(&mut ctx);
        module.finalize_definitions().map_err(|e| codegen(&e))?;
        let code = module.get_finalized_function(id);
        // SAFETY: `code` is the finalized, executable code of the function declared above
        // with three pointer parameters, no results and the platform's C calling convention —
        // `Entry`'s signature.
        Ok(unsafe { std::mem::transmute::<*const u8, Entry>(code) })
    }
}

/// `extern "C"` wrappers of the functions of the table, each `f.apply(&[a, b])` as the
/// interpreter calls it, and `func`, which picks one (an exhaustive match: a new function
/// of the table does not compile without its wrapper).
macro_rules! wrappers {
    ($($name:ident => $f:ident),* $(,)?) => {
        $(
            /// The function of the table of that name, as the interpreter calls it.
            extern "C" fn $name(a: f64, b: f64) -> f64 {
                Func::$f.apply(&[a, b])
            }
        )*
        /// The wrapper of `f`.
        fn func(f: Func) -> extern "C" fn(f64, f64) -> f64 {
            match f {
                $(Func::$f => $name,)*
            }
        }
    };
}

wrappers! {
    jit_sqrt => Sqrt,
    jit_sin => Sin,
    jit_cos => Cos,
    jit_tan => Tan,
    jit_asin => Asin,
    jit_acos => Acos,
    jit_atan => Atan,
    jit_exp => Exp,
    jit_ln => Ln,
    jit_atan2 => Atan2,
}

/// `a.powi(k)`, as the interpreter's `Powi`.
extern "C" fn jit_powi(a: f64, k: i32) -> f64 {
    a.powi(k)
}

/// [`eval::pow`], as the interpreter's `Powf`.
extern "C" fn jit_powf(a: f64, b: f64) -> f64 {
    eval::pow(a, b)
}

/// [`norm2`], as the interpreter's `Norm2`.
extern "C" fn jit_norm2(a: f64, b: f64) -> f64 {
    norm2(a, b)
}

/// [`norm3`], as the interpreter's `Norm3`.
extern "C" fn jit_norm3(a: f64, b: f64, c: f64) -> f64 {
    norm3(a, b, c)
}
