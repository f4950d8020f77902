//! The [`Field`] trait: what a mesher needs from an implicit function.

/// A scalar field f(x, y, z) with f >= 0 inside the solid, evaluated in bulk.
///
/// The meshers call it with batches of points, never one point per call, and with boxes for
/// interval pruning. `fdsl` implements it over its compiled tapes; tests implement it over
/// closed-form functions.
pub trait Field {
    /// Conservative bounds `(lo, hi)` of f over the box `lo..=hi`.
    ///
    /// Every value of f at a point of the closed box must lie in the returned range.
    /// NaN bounds mean "unknown" and disable pruning of that box.
    fn interval(&mut self, lo: [f32; 3], hi: [f32; 3]) -> (f32, f32);

    /// Writes f at each point `(xs[i], ys[i], zs[i])` to `out[i]`; all slices have equal length.
    fn values(&mut self, xs: &[f32], ys: &[f32], zs: &[f32], out: &mut [f32]);

    /// Writes the gradient of f at each point to `out[i]`.
    ///
    /// The default uses central differences through [`Field::values`], in one bulk call;
    /// fields with forward-mode derivatives should override it.
    fn gradients(&mut self, xs: &[f32], ys: &[f32], zs: &[f32], out: &mut [[f32; 3]]) {
        let n = xs.len();
        let mut px = Vec::with_capacity(6 * n);
        let mut py = Vec::with_capacity(6 * n);
        let mut pz = Vec::with_capacity(6 * n);
        for i in 0..n {
            let p = [xs[i], ys[i], zs[i]];
            let h = p.map(|c| GRADIENT_STEP_RELATIVE * c.abs().max(1.0));
            for axis in 0..3 {
                for sign in [1.0f32, -1.0] {
                    let mut q = p;
                    q[axis] += sign * h[axis];
                    px.push(q[0]);
                    py.push(q[1]);
                    pz.push(q[2]);
                }
            }
        }
        let mut v = vec![0.0f32; 6 * n];
        self.values(&px, &py, &pz, &mut v);
        for (i, g) in out.iter_mut().enumerate().take(n) {
            let base = 6 * i;
            for axis in 0..3 {
                // Recompute the step actually taken, so rounding of p + h does not bias it.
                let c = [xs[i], ys[i], zs[i]][axis];
                let h = GRADIENT_STEP_RELATIVE * c.abs().max(1.0);
                g[axis] = (v[base + 2 * axis] - v[base + 2 * axis + 1]) / (2.0 * h);
            }
        }
    }

    /// A field equal to `self` on the box `lo..=hi`, but cheaper there, or `None`.
    ///
    /// This is the hook for tape simplification: an evaluator may drop the branches of
    /// `min`/`max` that interval arithmetic proves irrelevant in the box. The mesher uses the
    /// returned field for everything inside that box.
    fn simplify(&mut self, lo: [f32; 3], hi: [f32; 3]) -> Option<Self>
    where
        Self: Sized,
    {
        let _ = (lo, hi);
        None
    }

    /// A field that evaluates as `self` does, bit for bit, for another thread to use (a
    /// parallel remesh's subtree whose field did not simplify); `None` where none can be made:
    /// that remesh then runs on one thread.
    fn fork(&self) -> Option<Self>
    where
        Self: Sized,
    {
        None
    }
}

/// Finite-difference step of the default [`Field::gradients`], relative to |coordinate|.
pub const GRADIENT_STEP_RELATIVE: f32 = 1e-3;
