//! Adam (Kingma & Ba) over named candle vars, with its moment estimates
//! exposed so that training can be checkpointed and resumed exactly.
//! (`candle_nn::AdamW` with zero weight decay computes the same update but
//! keeps its state private.)

use crate::net::checkpoint::TensorMap;
use crate::{Error, Result};
use candle_core::backprop::GradStore;
use candle_core::{Tensor, Var};

/// Adam hyper-parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AdamParams {
    /// Learning rate.
    pub lr: f64,
    /// First-moment decay.
    pub beta1: f64,
    /// Second-moment decay.
    pub beta2: f64,
    /// Denominator guard.
    pub eps: f64,
}

impl Default for AdamParams {
    fn default() -> Self {
        AdamParams {
            lr: 1e-4,
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-8,
        }
    }
}

/// The optimiser: one (m, v) pair per var.
#[derive(Debug)]
pub struct Adam {
    vars: Vec<(String, Var)>,
    m: Vec<Tensor>,
    v: Vec<Tensor>,
    step: u64,
    params: AdamParams,
}

impl Adam {
    /// Start with zero moments.
    pub fn new(vars: Vec<(String, Var)>, params: AdamParams) -> candle_core::Result<Adam> {
        let m = vars
            .iter()
            .map(|(_, v)| v.as_tensor().zeros_like())
            .collect::<candle_core::Result<Vec<_>>>()?;
        let v = m.clone();
        Ok(Adam {
            vars,
            m,
            v,
            step: 0,
            params,
        })
    }

    /// Set the learning rate (the schedule calls this every epoch).
    pub fn set_lr(&mut self, lr: f64) {
        self.params.lr = lr;
    }

    /// Number of updates so far.
    pub fn steps(&self) -> u64 {
        self.step
    }

    /// One update from the gradients of a backward pass; vars without a
    /// gradient are left alone.
    pub fn step(&mut self, grads: &GradStore) -> candle_core::Result<()> {
        self.step += 1;
        let p = self.params;
        let t = self.step as i32;
        let c1 = 1.0 - p.beta1.powi(t);
        let c2 = 1.0 - p.beta2.powi(t);
        for (i, (_, var)) in self.vars.iter().enumerate() {
            let Some(g) = grads.get(var.as_tensor()) else {
                continue;
            };
            let m = ((&self.m[i] * p.beta1)? + (g * (1.0 - p.beta1))?)?;
            let v = ((&self.v[i] * p.beta2)? + (g.sqr()? * (1.0 - p.beta2))?)?;
            let denom = ((&v / c2)?.sqrt()? + p.eps)?;
            let update = ((&m / c1)? / denom)?;
            var.set(&(var.as_tensor() - (update * p.lr)?)?)?;
            self.m[i] = m;
            self.v[i] = v;
        }
        Ok(())
    }

    /// The moments as named tensors (`m.<var>`, `v.<var>`).
    pub fn state(&self) -> Vec<(String, Tensor)> {
        let mut out = Vec::with_capacity(2 * self.vars.len());
        for (i, (name, _)) in self.vars.iter().enumerate() {
            out.push((format!("m.{name}"), self.m[i].clone()));
            out.push((format!("v.{name}"), self.v[i].clone()));
        }
        out
    }

    /// Restore moments written by [`Adam::state`] and the step count.
    pub fn restore(&mut self, state: &TensorMap, step: u64) -> Result<()> {
        for (i, (name, var)) in self.vars.iter().enumerate() {
            for (kind, slot) in [("m", &mut self.m[i]), ("v", &mut self.v[i])] {
                let key = format!("{kind}.{name}");
                let (shape, values) = state.get(&key).ok_or_else(|| {
                    Error::invalid("optimizer", format!("tensor {key:?} is missing"))
                })?;
                if shape.as_slice() != var.dims() {
                    return Err(Error::invalid(
                        "optimizer",
                        format!(
                            "tensor {key:?}: expected shape {:?}, found {shape:?}",
                            var.dims()
                        ),
                    ));
                }
                *slot = Tensor::from_slice(values, shape.as_slice(), var.device())
                    .map_err(crate::net::candle_error)?;
            }
        }
        self.step = step;
        Ok(())
    }
}
