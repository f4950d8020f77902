//! The f64 single-point evaluator: the reference semantics, fast enough for 1 kHz haptics.

use crate::tape::{Code, Operand, Tape};

/// Evaluates a tape at one point in f64.
#[derive(Clone, Debug)]
pub struct PointEval {
    tape: Tape,
    regs: Vec<f64>,
}

impl PointEval {
    /// An evaluator for `tape` (allocates its registers once).
    pub fn new(tape: &Tape) -> PointEval {
        PointEval {
            tape: tape.clone(),
            regs: vec![0.0; tape.n_regs()],
        }
    }

    /// The tape this evaluator runs.
    pub fn tape(&self) -> &Tape {
        &self.tape
    }

    #[inline]
    fn run(&mut self, p: [f64; 4]) {
        for (slot, reg) in self.tape.inputs().iter().enumerate() {
            if let Some(r) = reg {
                self.regs[*r as usize] = p[slot];
            }
        }
        let regs = &mut self.regs;
        let grids = self.tape.grids();
        for instr in self.tape.instrs().iter() {
            let get = |o: Operand| match o {
                Operand::Reg(r) => regs[r as usize],
                Operand::Const(c) => c,
            };
            let [a, b, c] = instr.args;
            let value = match instr.code {
                Code::Unary(op) => op.apply(get(a)),
                Code::Binary(op) => op.apply(get(a), get(b)),
                Code::Ternary(op) => op.apply(get(a), get(b), get(c)),
                Code::Sample(g) => grids[g as usize].value([get(a), get(b), get(c)]),
            };
            regs[instr.out as usize] = value;
        }
    }

    #[inline]
    fn output(&self, o: Operand) -> f64 {
        match o {
            Operand::Reg(r) => self.regs[r as usize],
            Operand::Const(c) => c,
        }
    }

    /// The first output at `p = [x, y, z, t]`.
    // Inlined where the object model samples (another crate), as when they were one crate.
    #[inline]
    pub fn eval(&mut self, p: [f64; 4]) -> f64 {
        self.run(p);
        self.output(self.tape.outputs()[0])
    }

    /// Every output at `p`, written to `out` (which must hold one value per output).
    pub fn eval_all(&mut self, p: [f64; 4], out: &mut [f64]) {
        assert_eq!(out.len(), self.tape.outputs().len(), "one slot per output");
        self.run(p);
        for (slot, o) in out.iter_mut().zip(self.tape.outputs().iter()) {
            *slot = self.output(*o);
        }
    }
}
