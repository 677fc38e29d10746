//! The 3x3, stride-1, same-padding convolution every conv block uses,
//! computed as im2col + one matrix product so that both the forward and
//! the backward pass are GEMMs (candle's CPU `conv2d` backward goes through
//! a direct `conv_transpose2d` loop that is several times slower).
//!
//! `Im2Col` (a candle custom op) turns `(B, C, H, W)` into the column
//! matrix `(C*9, B*H*W)`, row `c*9 + ky*3 + kx`, column `b*H*W + y*W + x`
//! holding `x[b, c, y + ky - 1, x + kx - 1]` (zero outside the image); its
//! gradient is the adjoint scatter-add `Col2Im`. The product with the
//! weight `(O, C*9)` and the bias use ordinary candle ops, so candle
//! differentiates them. Parameters are named and shaped like
//! `candle_nn::conv2d` (`weight (O, C, 3, 3)`, `bias (O)`), so checkpoints
//! are interchangeable with it.

use candle_core::{CpuStorage, CustomOp1, Layout, Module, Result, Shape, Tensor};
use candle_nn::VarBuilder;

/// A 3x3 convolution with padding 1 and stride 1.
#[derive(Clone, Debug)]
pub struct Conv3x3 {
    weight: Tensor,
    bias: Tensor,
}

impl Conv3x3 {
    /// Build `inputs -> outputs` channels under `vb` (`weight`, `bias`).
    pub fn new(inputs: usize, outputs: usize, vb: VarBuilder) -> Result<Conv3x3> {
        let bound = 1.0 / ((inputs * 9) as f64).sqrt();
        let init = candle_nn::Init::Uniform {
            lo: -bound,
            up: bound,
        };
        let weight = vb.get_with_hints((outputs, inputs, 3, 3), "weight", init)?;
        let bias = vb.get_with_hints(outputs, "bias", init)?;
        Ok(Conv3x3 { weight, bias })
    }
}

impl Module for Conv3x3 {
    /// `(B, C, H, W) -> (B, O, H, W)`.
    fn forward(&self, x: &Tensor) -> Result<Tensor> {
        let (b, c, h, w) = x.dims4()?;
        let (o, wc, _, _) = self.weight.dims4()?;
        if wc != c {
            candle_core::bail!("conv3x3: input has {c} channels, the weight expects {wc}");
        }
        let cols = x.contiguous()?.apply_op1(Im2Col)?;
        let out = self.weight.reshape((o, c * 9))?.matmul(&cols)?;
        out.reshape((o, b, h, w))?
            .transpose(0, 1)?
            .contiguous()?
            .broadcast_add(&self.bias.reshape((1, o, 1, 1))?)
    }
}

/// `(B, C, H, W)` to the 3x3 column matrix `(C*9, B*H*W)`.
#[derive(Clone, Copy, Debug)]
pub struct Im2Col;

/// The adjoint of [`Im2Col`]: `(C*9, B*H*W)` columns scatter-added back to
/// `(B, C, H, W)` (the shape is carried by the op).
#[derive(Clone, Copy, Debug)]
pub struct Col2Im {
    /// `(B, C, H, W)` of the image side.
    pub dims: (usize, usize, usize, usize),
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

/// Destination columns `[x0, x1)` and the source column offset of a
/// horizontal kernel tap `kx` on a row of width `w`.
fn tap_span(kx: usize, w: usize) -> (usize, usize) {
    match kx {
        0 => (1, w),
        1 => (0, w),
        _ => (0, w.saturating_sub(1)),
    }
}

impl CustomOp1 for Im2Col {
    fn name(&self) -> &'static str {
        "im2col3x3"
    }

    fn cpu_fwd(&self, storage: &CpuStorage, layout: &Layout) -> Result<(CpuStorage, Shape)> {
        let (b, c, h, w) = layout.shape().dims4()?;
        let x = contiguous_f32(storage, layout, self.name())?;
        let n = b * h * w;
        let mut cols = vec![0f32; c * 9 * n];
        for ci in 0..c {
            for tap in 0..9 {
                let (ky, kx) = (tap / 3, tap % 3);
                let (x0, x1) = tap_span(kx, w);
                let row = &mut cols[(ci * 9 + tap) * n..(ci * 9 + tap + 1) * n];
                for bi in 0..b {
                    let image = &x[(bi * c + ci) * h * w..(bi * c + ci + 1) * h * w];
                    for y in 0..h {
                        let sy = y + ky;
                        if sy < 1 || sy > h {
                            continue;
                        }
                        let src = &image[(sy - 1) * w..sy * w];
                        let dst = &mut row[bi * h * w + y * w..bi * h * w + (y + 1) * w];
                        // x + kx - 1 in [0, w) for x in [x0, x1).
                        dst[x0..x1].copy_from_slice(&src[x0 + kx - 1..x1 + kx - 1]);
                    }
                }
            }
        }
        Ok((CpuStorage::F32(cols), Shape::from((c * 9, n))))
    }

    fn bwd(&self, arg: &Tensor, _res: &Tensor, grad_res: &Tensor) -> Result<Option<Tensor>> {
        let grad = grad_res
            .contiguous()?
            .apply_op1(Col2Im { dims: arg.dims4()? })?;
        Ok(Some(grad))
    }
}

impl CustomOp1 for Col2Im {
    fn name(&self) -> &'static str {
        "col2im3x3"
    }

    fn cpu_fwd(&self, storage: &CpuStorage, layout: &Layout) -> Result<(CpuStorage, Shape)> {
        let (b, c, h, w) = self.dims;
        let n = b * h * w;
        if layout.shape().dims() != [c * 9, n] {
            candle_core::bail!(
                "col2im3x3: columns {:?} do not match the image {:?}",
                layout.shape().dims(),
                self.dims
            );
        }
        let cols = contiguous_f32(storage, layout, self.name())?;
        let mut x = vec![0f32; b * c * h * w];
        for bi in 0..b {
            for ci in 0..c {
                let image = &mut x[(bi * c + ci) * h * w..(bi * c + ci + 1) * h * w];
                for tap in 0..9 {
                    let (ky, kx) = (tap / 3, tap % 3);
                    let (x0, x1) = tap_span(kx, w);
                    let row = &cols[(ci * 9 + tap) * n..(ci * 9 + tap + 1) * n];
                    for y in 0..h {
                        let sy = y + ky;
                        if sy < 1 || sy > h {
                            continue;
                        }
                        let src = &row[bi * h * w + y * w..bi * h * w + (y + 1) * w];
                        let dst = &mut image[(sy - 1) * w..sy * w];
                        for (d, s) in dst[x0 + kx - 1..x1 + kx - 1].iter_mut().zip(&src[x0..x1]) {
                            *d += s;
                        }
                    }
                }
            }
        }
        Ok((CpuStorage::F32(x), Shape::from(self.dims)))
    }

    fn bwd(&self, _arg: &Tensor, _res: &Tensor, grad_res: &Tensor) -> Result<Option<Tensor>> {
        Ok(Some(grad_res.contiguous()?.apply_op1(Im2Col)?))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::net::test_support::max_abs_diff;
    use candle_core::{DType, Device, Var};
    use candle_nn::VarMap;

    fn layer(c: usize, o: usize) -> (VarMap, Conv3x3) {
        let varmap = VarMap::new();
        let vb = VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu);
        let conv = Conv3x3::new(c, o, vb).unwrap();
        (varmap, conv)
    }

    #[test]
    fn forward_equals_candle_conv2d() {
        for &(b, c, o, h, w) in &[(2, 3, 4, 7, 5), (1, 1, 1, 1, 1), (3, 5, 2, 2, 9)] {
            let (_, conv) = layer(c, o);
            let x = Tensor::randn(0f32, 1f32, (b, c, h, w), &Device::Cpu).unwrap();
            let ours = conv.forward(&x).unwrap();
            let reference = x
                .conv2d(&conv.weight, 1, 1, 1, 1)
                .unwrap()
                .broadcast_add(&conv.bias.reshape((1, o, 1, 1)).unwrap())
                .unwrap();
            assert_eq!(ours.dims(), &[b, o, h, w]);
            assert!(max_abs_diff(&ours, &reference) < 1e-5);
        }
    }

    #[test]
    fn gradients_equal_candle_conv2d() {
        let (b, c, o, h, w) = (2, 3, 4, 6, 5);
        let (varmap, conv) = layer(c, o);
        let x = Var::randn(0f32, 1f32, (b, c, h, w), &Device::Cpu).unwrap();
        let target = Tensor::randn(0f32, 1f32, (b, o, h, w), &Device::Cpu).unwrap();
        let loss = |y: Tensor| (y * &target).unwrap().sum_all().unwrap();
        let ours = loss(conv.forward(x.as_tensor()).unwrap())
            .backward()
            .unwrap();
        let reference = loss(
            x.as_tensor()
                .conv2d(&conv.weight, 1, 1, 1, 1)
                .unwrap()
                .broadcast_add(&conv.bias.reshape((1, o, 1, 1)).unwrap())
                .unwrap(),
        )
        .backward()
        .unwrap();
        let mut checked = 1;
        assert!(
            max_abs_diff(
                ours.get(x.as_tensor()).unwrap(),
                reference.get(x.as_tensor()).unwrap()
            ) < 1e-4
        );
        for var in varmap.all_vars() {
            let (g, r) = (ours.get(&var).unwrap(), reference.get(&var).unwrap());
            assert!(max_abs_diff(g, r) < 1e-4);
            checked += 1;
        }
        assert_eq!(checked, 3);
    }

    #[test]
    fn col2im_is_the_adjoint_of_im2col() {
        // <im2col(x), g> == <x, col2im(g)> for random x, g.
        let dims = (2, 3, 4, 5);
        let x = Tensor::randn(0f32, 1f32, dims, &Device::Cpu).unwrap();
        let g = Tensor::randn(0f32, 1f32, (27, 40), &Device::Cpu).unwrap();
        let lhs = (x.apply_op1(Im2Col).unwrap() * &g)
            .unwrap()
            .sum_all()
            .unwrap()
            .to_scalar::<f32>()
            .unwrap();
        let rhs = (x * g.apply_op1(Col2Im { dims }).unwrap())
            .unwrap()
            .sum_all()
            .unwrap()
            .to_scalar::<f32>()
            .unwrap();
        assert!((lhs - rhs).abs() < 1e-4 * lhs.abs().max(1.0));
    }
}
