//! The task-space term of the training loss: the squared distance between
//! the TCP positions of the predicted and the demonstrated mean final
//! configurations, through forward kinematics written in candle ops so it
//! differentiates.
//!
//! Why: the joint-space losses (Eq. 7, Eq. 8) treat every joint alike, but
//! a demonstrator's arm is redundant. Two nearby berries can be reached on
//! two different elbow branches (on the synthetic data 9 % of target pairs
//! closer than 2 cm differ by more than 0.3 rad in some joint), and a
//! regressor in joint space then predicts the average of the branches,
//! whose TCP misses both. The task-space term rewards a configuration that
//! puts the hand where the demonstrations did, whichever posture gets it
//! there, while Eq. 7 keeps the posture and the timing human-like.
//!
//! The term is `mean_b |FK(phi_T^T mu_hat_b) - FK(phi_T^T mu_b)|^2 / s^2`
//! with `s` = [`TCP_LOSS_SCALE_M`] (1 cm of TCP error costs 1), weighted by
//! `tcp_weight` in the phase objectives.

use crate::promp::Basis;
use crate::robot::chain::Motion;
use crate::robot::Robot;
use candle_core::{DType, Device, Result, Tensor, D};
use nalgebra::Matrix3;

/// TCP error that costs one unit of loss (m).
pub const TCP_LOSS_SCALE_M: f64 = 0.01;

/// One chain step as constant tensors.
#[derive(Clone, Debug)]
struct StepTensors {
    /// Joint origin rotation `(3, 3)` and translation `(3, 1)`.
    rotation: Tensor,
    translation: Tensor,
    motion: StepMotion,
}

#[derive(Clone, Debug)]
enum StepMotion {
    Fixed,
    /// Rodrigues: `R(q) = I + sin q K + (1 - cos q) K^2`, `K` the axis' cross matrix.
    Revolute {
        k: Tensor,
        k2: Tensor,
        dof: usize,
    },
    /// Translation `axis * q` in the joint frame; `axis` is `(3, 1)`.
    Prismatic {
        axis: Tensor,
        dof: usize,
    },
}

/// Batched forward kinematics of the TCP position, differentiable in `q`.
#[derive(Clone, Debug)]
pub struct TcpKinematics {
    steps: Vec<StepTensors>,
    dof: usize,
}

fn matrix_tensor(m: &Matrix3<f64>, device: &Device) -> Result<Tensor> {
    let values: Vec<f32> = (0..3)
        .flat_map(|r| (0..3).map(move |c| m[(r, c)] as f32))
        .collect();
    Tensor::from_vec(values, (3, 3), device)
}

fn column_tensor(v: &nalgebra::Vector3<f64>, device: &Device) -> Result<Tensor> {
    Tensor::from_vec(v.iter().map(|&x| x as f32).collect(), (3, 1), device)
}

impl TcpKinematics {
    /// Compile the robot's chain to constant tensors.
    pub fn new(robot: &Robot, device: &Device) -> Result<TcpKinematics> {
        let steps = robot
            .steps
            .iter()
            .map(|step| {
                let rotation =
                    matrix_tensor(step.origin.rotation.to_rotation_matrix().matrix(), device)?;
                let translation = column_tensor(&step.origin.translation.vector, device)?;
                let motion = match step.motion {
                    Motion::Fixed => StepMotion::Fixed,
                    Motion::Revolute { axis, dof } => {
                        let k = axis.into_inner().cross_matrix();
                        StepMotion::Revolute {
                            k: matrix_tensor(&k, device)?,
                            k2: matrix_tensor(&(k * k), device)?,
                            dof,
                        }
                    }
                    Motion::Prismatic { axis, dof } => StepMotion::Prismatic {
                        axis: column_tensor(&axis.into_inner(), device)?,
                        dof,
                    },
                };
                Ok(StepTensors {
                    rotation,
                    translation,
                    motion,
                })
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(TcpKinematics {
            steps,
            dof: robot.dof(),
        })
    }

    /// TCP positions `(B, 3)` of the configurations `q` `(B, dof)`.
    pub fn positions(&self, q: &Tensor) -> Result<Tensor> {
        let (b, dof) = q.dims2()?;
        if dof != self.dof {
            candle_core::bail!("expected {} joint values per row, got {dof}", self.dof);
        }
        let device = q.device();
        let eye = Tensor::eye(3, DType::F32, device)?;
        let mut rotation = eye.unsqueeze(0)?.broadcast_as((b, 3, 3))?.contiguous()?;
        let mut position = Tensor::zeros((b, 3, 1), DType::F32, device)?;
        for step in &self.steps {
            position = (position + rotation.broadcast_matmul(&step.translation)?)?;
            rotation = rotation.broadcast_matmul(&step.rotation)?;
            match &step.motion {
                StepMotion::Fixed => {}
                StepMotion::Revolute { k, k2, dof } => {
                    let angle = q.narrow(1, *dof, 1)?.unsqueeze(2)?;
                    let joint = (eye.unsqueeze(0)?.broadcast_add(
                        &(k.unsqueeze(0)?.broadcast_mul(&angle.sin()?)?
                            + k2.unsqueeze(0)?.broadcast_mul(&(1.0 - angle.cos()?)?)?)?,
                    ))?;
                    rotation = rotation.matmul(&joint)?;
                }
                StepMotion::Prismatic { axis, dof } => {
                    let shift = q.narrow(1, *dof, 1)?.unsqueeze(2)?;
                    let moved = rotation.broadcast_matmul(axis)?.broadcast_mul(&shift)?;
                    position = (position + moved)?;
                }
            }
        }
        position.squeeze(D::Minus1)
    }
}

/// The task-space loss term of a model's basis.
#[derive(Clone, Debug)]
pub struct TcpLoss {
    kinematics: TcpKinematics,
    /// `(n_basis, 1)`: the basis at the last phase sample.
    last: Tensor,
}

impl TcpLoss {
    /// Build for `robot` and the ProMP `basis`.
    pub fn new(robot: &Robot, basis: &Basis, device: &Device) -> Result<TcpLoss> {
        let matrix = basis.matrix();
        let row = matrix.nrows() - 1;
        let last: Vec<f32> = (0..matrix.ncols())
            .map(|c| matrix[(row, c)] as f32)
            .collect();
        Ok(TcpLoss {
            kinematics: TcpKinematics::new(robot, device)?,
            last: Tensor::from_vec(last, (matrix.ncols(), 1), device)?,
        })
    }

    /// Final configurations `(B, J)` of weight means `(B, J, n)`.
    pub fn final_configurations(&self, mean: &Tensor) -> Result<Tensor> {
        mean.broadcast_matmul(&self.last)?.squeeze(D::Minus1)
    }

    /// `mean_b |TCP(pred) - TCP(target)|^2 / s^2` for weight means
    /// `(B, J, n)`.
    pub fn loss(&self, pred_mean: &Tensor, target_mean: &Tensor) -> Result<Tensor> {
        let predicted = self
            .kinematics
            .positions(&self.final_configurations(pred_mean)?)?;
        let target = self
            .kinematics
            .positions(&self.final_configurations(target_mean)?)?
            .detach();
        let scale = 1.0 / (TCP_LOSS_SCALE_M * TCP_LOSS_SCALE_M);
        (predicted - target)?.sqr()?.sum(1)?.mean_all()? * scale
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    fn random_configurations(robot: &Robot, count: usize) -> Vec<Vec<f64>> {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        (0..count)
            .map(|_| {
                robot
                    .limits()
                    .iter()
                    .map(|l| rng.gen_range(l.lower..l.upper))
                    .collect()
            })
            .collect()
    }

    fn as_tensor(qs: &[Vec<f64>]) -> Tensor {
        let flat: Vec<f32> = qs.iter().flatten().map(|&v| v as f32).collect();
        Tensor::from_vec(flat, (qs.len(), qs[0].len()), &Device::Cpu).unwrap()
    }

    #[test]
    fn batched_kinematics_match_the_robot_forward_kinematics() {
        let robot = Robot::panda().unwrap();
        let kin = TcpKinematics::new(&robot, &Device::Cpu).unwrap();
        let qs = random_configurations(&robot, 64);
        let got = kin
            .positions(&as_tensor(&qs))
            .unwrap()
            .to_vec2::<f32>()
            .unwrap();
        for (q, p) in qs.iter().zip(&got) {
            let want = robot.tcp_pose(q).translation.vector;
            for k in 0..3 {
                assert!(
                    (f64::from(p[k]) - want[k]).abs() < 2e-6,
                    "{q:?}: {p:?} vs {want:?}"
                );
            }
        }
    }

    #[test]
    fn gradient_matches_finite_differences_of_the_robot_kinematics() {
        let robot = Robot::panda().unwrap();
        let kin = TcpKinematics::new(&robot, &Device::Cpu).unwrap();
        for q in random_configurations(&robot, 8) {
            let var = candle_core::Var::from_tensor(&as_tensor(std::slice::from_ref(&q))).unwrap();
            // d/dq of (x + 2 y + 3 z) of the TCP.
            let weights = Tensor::new(&[[1.0f32], [2.0], [3.0]], &Device::Cpu).unwrap();
            let objective = kin
                .positions(var.as_tensor())
                .unwrap()
                .matmul(&weights)
                .unwrap()
                .sum_all()
                .unwrap();
            let grads = objective.backward().unwrap();
            let grad = grads
                .get(var.as_tensor())
                .unwrap()
                .to_vec2::<f32>()
                .unwrap();
            let f = |q: &[f64]| {
                let p = robot.tcp_pose(q).translation.vector;
                p.x + 2.0 * p.y + 3.0 * p.z
            };
            for j in 0..q.len() {
                let h = 1e-6;
                let (mut up, mut down) = (q.clone(), q.clone());
                up[j] += h;
                down[j] -= h;
                let fd = (f(&up) - f(&down)) / (2.0 * h);
                assert!(
                    (f64::from(grad[0][j]) - fd).abs() < 1e-4,
                    "joint {j}: autograd {} vs finite differences {fd}",
                    grad[0][j]
                );
            }
        }
    }

    #[test]
    fn the_loss_is_the_scaled_squared_tcp_distance() {
        let robot = Robot::panda().unwrap();
        let basis = Basis::new(&crate::promp::PrompConfig::default()).unwrap();
        let loss = TcpLoss::new(&robot, &basis, &Device::Cpu).unwrap();
        let n = basis.n_basis();
        // Weights that make every phase sample equal q (the basis is
        // normalised, so constant weights give a constant trajectory).
        let to_mean = |q: &[f64]| {
            let flat: Vec<f32> = q.iter().flat_map(|&v| vec![v as f32; n]).collect();
            Tensor::from_vec(flat, (1, q.len(), n), &Device::Cpu).unwrap()
        };
        let qs = random_configurations(&robot, 2);
        let value = loss
            .loss(&to_mean(&qs[0]), &to_mean(&qs[1]))
            .unwrap()
            .to_scalar::<f32>()
            .unwrap();
        let d = (robot.tcp_pose(&qs[0]).translation.vector
            - robot.tcp_pose(&qs[1]).translation.vector)
            .norm();
        let want = (d / TCP_LOSS_SCALE_M).powi(2);
        assert!(
            (f64::from(value) - want).abs() < 1e-4 * want,
            "{value} vs {want}"
        );
    }
}
