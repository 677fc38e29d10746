//! Element-wise and resampling layers as single-pass candle custom ops with
//! explicit backward passes: LeakyReLU and 2x nearest-neighbour upsampling.
//! candle composes LeakyReLU from four ops (and differentiates
//! `maximum`/`minimum` through comparison masks) and differentiates nearest
//! upsampling through a grouped convolution; on 128x128 feature maps these
//! dominated the training step. Same values as
//! `candle_nn::ops::leaky_relu` and `Tensor::upsample_nearest2d`.

use candle_core::{CpuStorage, CustomOp1, CustomOp2, Layout, Result, Shape, Tensor};

/// `x` where `x > 0`, else `slope * x` (one pass; gradient one pass).
pub fn leaky_relu(x: &Tensor, slope: f64) -> Result<Tensor> {
    x.contiguous()?.apply_op1(LeakyRelu {
        slope: slope as f32,
    })
}

/// Nearest-neighbour 2x upsampling `(B, C, H, W) -> (B, C, 2H, 2W)`.
pub fn upsample2x(x: &Tensor) -> Result<Tensor> {
    x.contiguous()?.apply_op1(Upsample2x)
}

fn contiguous_f32<'a>(storage: &'a CpuStorage, layout: &Layout, op: &str) -> Result<&'a [f32]> {
    let CpuStorage::F32(data) = storage else {
        candle_core::bail!("{op}: only f32 is supported");
    };
    match layout.contiguous_offsets() {
        Some((start, end)) => Ok(&data[start..end]),
        None => candle_core::bail!("{op}: the input must be contiguous"),
    }
}

/// The LeakyReLU op.
#[derive(Clone, Copy, Debug)]
struct LeakyRelu {
    slope: f32,
}

/// `grad * (x > 0 ? 1 : slope)`, arguments `(grad, x)`.
#[derive(Clone, Copy, Debug)]
struct LeakyReluGrad {
    slope: f32,
}

impl CustomOp1 for LeakyRelu {
    fn name(&self) -> &'static str {
        "leaky_relu"
    }

    fn cpu_fwd(&self, storage: &CpuStorage, layout: &Layout) -> Result<(CpuStorage, Shape)> {
        let x = contiguous_f32(storage, layout, self.name())?;
        let s = self.slope;
        let out = x.iter().map(|&v| if v > 0.0 { v } else { s * v }).collect();
        Ok((CpuStorage::F32(out), layout.shape().clone()))
    }

    fn bwd(&self, arg: &Tensor, _res: &Tensor, grad_res: &Tensor) -> Result<Option<Tensor>> {
        let grad = grad_res
            .contiguous()?
            .apply_op2_no_bwd(&arg.contiguous()?, &LeakyReluGrad { slope: self.slope })?;
        Ok(Some(grad))
    }
}

impl CustomOp2 for LeakyReluGrad {
    fn name(&self) -> &'static str {
        "leaky_relu_grad"
    }

    fn cpu_fwd(
        &self,
        s1: &CpuStorage,
        l1: &Layout,
        s2: &CpuStorage,
        l2: &Layout,
    ) -> Result<(CpuStorage, Shape)> {
        let g = contiguous_f32(s1, l1, self.name())?;
        let x = contiguous_f32(s2, l2, self.name())?;
        if g.len() != x.len() {
            candle_core::bail!(
                "leaky_relu_grad: {} gradients for {} inputs",
                g.len(),
                x.len()
            );
        }
        let s = self.slope;
        let out = g
            .iter()
            .zip(x)
            .map(|(&g, &x)| if x > 0.0 { g } else { s * g })
            .collect();
        Ok((CpuStorage::F32(out), l1.shape().clone()))
    }
}

/// The 2x nearest upsampling op.
#[derive(Clone, Copy, Debug)]
struct Upsample2x;

/// Its adjoint: the sum of every 2x2 block, `(B, C, 2H, 2W) -> (B, C, H, W)`.
#[derive(Clone, Copy, Debug)]
struct SumPool2x;

impl CustomOp1 for Upsample2x {
    fn name(&self) -> &'static str {
        "upsample_nearest2x"
    }

    fn cpu_fwd(&self, storage: &CpuStorage, layout: &Layout) -> Result<(CpuStorage, Shape)> {
        let (b, c, h, w) = layout.shape().dims4()?;
        let x = contiguous_f32(storage, layout, self.name())?;
        let mut out = vec![0f32; b * c * 4 * h * w];
        for (plane, src) in out.chunks_mut(4 * h * w).zip(x.chunks(h * w)) {
            for (y, row) in src.chunks(w).enumerate() {
                let top = &mut plane[2 * y * 2 * w..(2 * y + 1) * 2 * w];
                for (pair, &v) in top.chunks_mut(2).zip(row) {
                    pair[0] = v;
                    pair[1] = v;
                }
                plane.copy_within(2 * y * 2 * w..(2 * y + 1) * 2 * w, (2 * y + 1) * 2 * w);
            }
        }
        Ok((CpuStorage::F32(out), Shape::from((b, c, 2 * h, 2 * w))))
    }

    fn bwd(&self, _arg: &Tensor, _res: &Tensor, grad_res: &Tensor) -> Result<Option<Tensor>> {
        Ok(Some(grad_res.contiguous()?.apply_op1_no_bwd(&SumPool2x)?))
    }
}

impl CustomOp1 for SumPool2x {
    fn name(&self) -> &'static str {
        "sum_pool2x"
    }

    fn cpu_fwd(&self, storage: &CpuStorage, layout: &Layout) -> Result<(CpuStorage, Shape)> {
        let (b, c, h2, w2) = layout.shape().dims4()?;
        if h2 % 2 != 0 || w2 % 2 != 0 {
            candle_core::bail!("sum_pool2x: odd size {h2}x{w2}");
        }
        let (h, w) = (h2 / 2, w2 / 2);
        let g = contiguous_f32(storage, layout, self.name())?;
        let mut out = vec![0f32; b * c * h * w];
        for (dst, plane) in out.chunks_mut(h * w).zip(g.chunks(4 * h * w)) {
            for (y, row) in dst.chunks_mut(w).enumerate() {
                let top = &plane[2 * y * w2..(2 * y + 1) * w2];
                let bottom = &plane[(2 * y + 1) * w2..(2 * y + 2) * w2];
                for (x, d) in row.iter_mut().enumerate() {
                    *d = top[2 * x] + top[2 * x + 1] + bottom[2 * x] + bottom[2 * x + 1];
                }
            }
        }
        Ok((CpuStorage::F32(out), Shape::from((b, c, h, w))))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::net::test_support::max_abs_diff;
    use candle_core::{Device, Var};

    /// Values and gradients (of `sum(f(x) * r)`) of ours against candle's.
    fn check(ours: impl Fn(&Tensor) -> Tensor, reference: impl Fn(&Tensor) -> Tensor) {
        let x = Var::randn(0f32, 1f32, (2, 3, 4, 5), &Device::Cpu).unwrap();
        let (a, b) = (ours(x.as_tensor()), reference(x.as_tensor()));
        assert_eq!(a.dims(), b.dims());
        assert!(max_abs_diff(&a, &b) < 1e-6);
        let r = Tensor::randn(0f32, 1f32, a.dims(), &Device::Cpu).unwrap();
        let ga = (a * &r).unwrap().sum_all().unwrap().backward().unwrap();
        let gb = (b * &r).unwrap().sum_all().unwrap().backward().unwrap();
        let (ga, gb) = (
            ga.get(x.as_tensor()).unwrap(),
            gb.get(x.as_tensor()).unwrap(),
        );
        assert!(max_abs_diff(ga, gb) < 1e-5);
    }

    #[test]
    fn leaky_relu_matches_candle() {
        check(
            |x| leaky_relu(x, 0.2).unwrap(),
            |x| candle_nn::ops::leaky_relu(x, 0.2).unwrap(),
        );
    }

    #[test]
    fn upsample_matches_candle() {
        check(
            |x| upsample2x(x).unwrap(),
            |x| x.upsample_nearest2d(8, 10).unwrap(),
        );
    }

    #[test]
    fn leaky_relu_gradient_is_one_or_slope() {
        let x = Var::new(&[-2f32, -0.5, 0.5, 3.0], &Device::Cpu).unwrap();
        let y = leaky_relu(x.as_tensor(), 0.2).unwrap();
        assert_eq!(y.to_vec1::<f32>().unwrap(), vec![-0.4, -0.1, 0.5, 3.0]);
        let g = y.sum_all().unwrap().backward().unwrap();
        let g = g.get(x.as_tensor()).unwrap().to_vec1::<f32>().unwrap();
        assert_eq!(g, vec![0.2, 0.2, 1.0, 1.0]);
    }
}
