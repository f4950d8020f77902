//! [`Function`]: a compiled function string with named outputs, the entry point of the crate.

use std::cell::Cell;
use std::fmt;
use std::sync::Arc;

use crate::compile::lower::{self, Lowered};
pub use crate::compile::lower::{Grids, Options, SetOps};
use crate::compile::{Context, Node};
use crate::syntax::diagnostic::render_all;
use crate::syntax::{Diagnostic, parser};
use crate::tape::Tape;

/// A compiled function string: an expression graph with one or more named outputs.
///
/// Outputs are named after what defines them: `value` for a single expression, a
/// `function frep(...)` or a top-level `return`; the variable name for statement lists
/// (`x`, `y`, `z` of a parametric definition, `r`, `g`, `b` of a colour); and `x`, `y`, `z` for
/// `function parametric_x/_y/_z(...)` of a vector field.
#[derive(Clone, Debug)]
pub struct Function {
    context: Arc<Context>,
    outputs: Vec<(String, Node)>,
    inputs_used: [bool; 4],
}

/// The result of compiling: the function when there was no error, and every diagnostic
/// (warnings too, for example a removed `BEGIN ... END` wrapper).
#[derive(Clone, Debug)]
pub struct Compiled {
    /// The function, unless an error was reported.
    pub function: Option<Function>,
    /// Errors and warnings, in source order of discovery.
    pub diagnostics: Vec<Diagnostic>,
}

/// Compiling failed: the source and its diagnostics, rendered with carets by `Display`.
#[derive(Clone, Debug, PartialEq)]
pub struct CompileError {
    /// The text that failed.
    pub source: String,
    /// What is wrong with it.
    pub diagnostics: Vec<Diagnostic>,
}

impl fmt::Display for CompileError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let errors: Vec<Diagnostic> = self
            .diagnostics
            .iter()
            .filter(|d| d.is_error())
            .cloned()
            .collect();
        write!(f, "{}", render_all(&errors, &self.source).trim_end())
    }
}

impl std::error::Error for CompileError {}

thread_local! {
    /// Texts compiled on this thread (every [`Function::compile_with`]).
    static N_COMPILED: Cell<u64> = const { Cell::new(0) };
}

/// How many texts this thread has compiled: every [`Function::compile`], whether the object
/// model's compile cache called it (a miss) or anything else did. What a test reads to show
/// that a formula is compiled once, and that nothing downstream (render, haptic) compiles an
/// object's text again.
pub fn n_compiled_on_this_thread() -> u64 {
    N_COMPILED.with(Cell::get)
}

/// A requested output does not exist.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("the definition has no output `{name}` (it defines {available})")]
pub struct MissingOutput {
    /// The name asked for.
    pub name: String,
    /// The names it has, comma-separated.
    pub available: String,
}

impl Function {
    /// Compiles a source text with the default options (`& | \` as min/max).
    pub fn compile(source: &str) -> Compiled {
        Function::compile_with(source, Options::default())
    }

    /// Compiles a source text.
    pub fn compile_with(source: &str, options: Options) -> Compiled {
        N_COMPILED.with(|n| n.set(n.get() + 1));
        let (program, mut diagnostics) = parser::parse(source);
        if diagnostics.iter().any(Diagnostic::is_error) {
            return Compiled {
                function: None,
                diagnostics,
            };
        }
        let (lowered, more) = lower::lower(&program, options);
        diagnostics.extend(more);
        let function = lowered.map(
            |Lowered {
                 context,
                 outputs,
                 inputs_used,
             }| Function {
                context: Arc::new(context),
                outputs,
                inputs_used,
            },
        );
        Compiled {
            function,
            diagnostics,
        }
    }

    /// Compiles, turning errors into a [`CompileError`] (warnings are dropped).
    ///
    /// ```
    /// let sphere = fdsl::Function::parse("1-x^2-y^2-z^2").unwrap();
    /// let mut eval = fdsl::eval::PointEval::new(&sphere.tape());
    /// assert_eq!(eval.eval([0.5, 0.0, 0.0, 0.0]), 0.75);
    /// assert!(fdsl::Function::parse("1-x^2-").is_err());
    /// ```
    pub fn parse(source: &str) -> Result<Function, CompileError> {
        Function::parse_with(source, Options::default())
    }

    /// [`Function::parse`] with options.
    pub fn parse_with(source: &str, options: Options) -> Result<Function, CompileError> {
        let compiled = Function::compile_with(source, options);
        compiled.function.ok_or_else(|| CompileError {
            source: source.to_string(),
            diagnostics: compiled.diagnostics,
        })
    }

    /// The names of the outputs, in definition order.
    pub fn output_names(&self) -> impl Iterator<Item = &str> {
        self.outputs.iter().map(|(n, _)| n.as_str())
    }

    /// Whether the function defines an output of this name.
    pub fn has_output(&self, name: &str) -> bool {
        self.outputs.iter().any(|(n, _)| n == name)
    }

    /// Which coordinate slots (x/u, y/v, z/w, t) the function reads.
    pub fn inputs_used(&self) -> [bool; 4] {
        self.inputs_used
    }

    /// Whether the function depends on time.
    pub fn depends_on_time(&self) -> bool {
        self.inputs_used[3]
    }

    /// The graph's size (distinct operations), a measure of the function's cost.
    pub fn graph_len(&self) -> usize {
        self.context.len()
    }

    /// A tape for the main value: the `value` output if there is one, else the first output.
    pub fn tape(&self) -> Tape {
        let node = self
            .outputs
            .iter()
            .find(|(n, _)| n == "value")
            .unwrap_or(&self.outputs[0])
            .1;
        Tape::new(&self.context, &[node])
    }

    /// A tape computing the named outputs together, in the order given (shared subexpressions
    /// are computed once).
    pub fn tape_for(&self, names: &[&str]) -> Result<Tape, MissingOutput> {
        let mut roots = Vec::with_capacity(names.len());
        for name in names {
            match self.outputs.iter().find(|(n, _)| n == name) {
                Some((_, node)) => roots.push(*node),
                None => {
                    let available = self
                        .outputs
                        .iter()
                        .map(|(n, _)| n.as_str())
                        .collect::<Vec<_>>()
                        .join(", ");
                    return Err(MissingOutput {
                        name: name.to_string(),
                        available,
                    });
                }
            }
        }
        Ok(Tape::new(&self.context, &roots))
    }
}
