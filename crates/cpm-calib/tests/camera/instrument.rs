//! A pinhole camera watching a marker on the platform: an instrument written outside
//! cpm-calib against its public API only (the `Instrument` trait), shared by the library's
//! test (`tests/camera.rs`) and the workflow's (`cpm-workflow/tests/camera.rs`).
//!
//! The camera's nominal pose and focal length are known roughly; its own block is the
//! correction of that pose (translation x y z um, rotation about the camera's x y z urad) and
//! of the focal length (px). One measurement is the marker's pixel position (u, v), px.
use cpm_calib::instruments::{Instrument, InstrumentInput};
use nalgebra::{DMatrix, Matrix3, Rotation3, Vector3};

/// A pinhole camera: nominal pose (camera-to-base rotation, centre in mm), focal length and
/// principal point (px), and the marker's position on the platform (mm, platform frame).
#[derive(Debug, Clone)]
pub struct Camera {
    pub rotation: Rotation3<f64>,
    pub centre_mm: Vector3<f64>,
    pub focal_px: f64,
    pub principal_px: [f64; 2],
    pub marker_mm: Vector3<f64>,
}

const NAMES: [&str; 7] = ["x", "y", "z", "rx", "ry", "rz", "focal"];

/// The skew matrix of `v` (`skew(v) w = v x w`).
fn skew(v: Vector3<f64>) -> Matrix3<f64> {
    v.cross_matrix()
}

impl Camera {
    /// A camera at `centre_mm` looking at `target_mm` (its y axis in the plane of the base's
    /// z), with focal length `focal_px`, watching `marker_mm` on the platform.
    pub fn looking_at(
        centre_mm: Vector3<f64>,
        target_mm: Vector3<f64>,
        focal_px: f64,
        marker_mm: Vector3<f64>,
    ) -> Self {
        let z = (target_mm - centre_mm).normalize();
        let x = z.cross(&Vector3::z()).normalize();
        let y = z.cross(&x);
        let rotation = Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[x, y, z]));
        Self {
            rotation,
            centre_mm,
            focal_px,
            principal_px: [2000.0, 1500.0],
            marker_mm,
        }
    }

    /// The camera's rotation and centre with the corrections `n` (urad, um), its focal length
    /// (px), and the rotation's derivatives with respect to the three angles (per rad).
    fn corrected(&self, n: &[f64]) -> (Matrix3<f64>, Vector3<f64>, f64, [Matrix3<f64>; 3]) {
        let [a, b, c] = [n[3], n[4], n[5]].map(|x| x * 1e-6);
        let rx = Rotation3::from_axis_angle(&Vector3::x_axis(), a).into_inner();
        let ry = Rotation3::from_axis_angle(&Vector3::y_axis(), b).into_inner();
        let rz = Rotation3::from_axis_angle(&Vector3::z_axis(), c).into_inner();
        let r0 = self.rotation.into_inner();
        // R = R0 Rx Ry Rz (small angles about the camera's own axes).
        let r = r0 * rx * ry * rz;
        let (ex, ey, ez) = (skew(Vector3::x()), skew(Vector3::y()), skew(Vector3::z()));
        let d = [r0 * rx * ex * ry * rz, r0 * rx * ry * ey * rz, r * ez];
        let t = self.centre_mm + Vector3::new(n[0], n[1], n[2]) * 1e-3;
        (r, t, self.focal_px + n[6], d)
    }

    /// The marker in the camera's frame, with the camera's corrected parameters.
    fn seen(
        &self,
        input: &InstrumentInput,
        n: &[f64],
    ) -> (Vector3<f64>, Vector3<f64>, Matrix3<f64>) {
        let (r, t, _, _) = self.corrected(n);
        let rq = input.pose.rotation * self.marker_mm;
        (r.transpose() * (input.pose.position_mm + rq - t), rq, r)
    }
}

impl Instrument for Camera {
    fn name(&self) -> &str {
        "camera"
    }
    fn num_values(&self) -> usize {
        2
    }
    fn unit(&self) -> &str {
        "px"
    }
    fn num_instrument_params(&self) -> usize {
        7
    }
    fn param_name(&self, k: usize) -> String {
        NAMES[k].to_string()
    }
    fn param_unit(&self, k: usize) -> &str {
        ["um", "um", "um", "urad", "urad", "urad", "px"][k]
    }
    fn predict(&self, input: &InstrumentInput, _: usize, n: &[f64], y: &mut [f64]) {
        let (x, _, _) = self.seen(input, n);
        let f = self.focal_px + n[6];
        y[0] = self.principal_px[0] + f * x.x / x.z;
        y[1] = self.principal_px[1] + f * x.y / x.z;
    }
    fn jacobian(
        &self,
        input: &InstrumentInput,
        _: usize,
        n: &[f64],
        d_pose: &mut DMatrix<f64>,
        d_n: &mut DMatrix<f64>,
    ) {
        let (x, rq, r) = self.seen(input, n);
        let (_, t, f, dr) = self.corrected(n);
        // (u, v) per unit of the marker in the camera's frame.
        let p = nalgebra::Matrix2x3::new(
            f / x.z,
            0.0,
            -f * x.x / (x.z * x.z),
            0.0,
            f / x.z,
            -f * x.y / (x.z * x.z),
        );
        let rt = r.transpose();
        // The marker moves by dp + dtheta x (R q): per twist of the platform.
        let dp = p * rt;
        let dw = p * rt * -skew(rq);
        let dt = -dp * 1e-3;
        let m = input.pose.position_mm + rq - t;
        for i in 0..2 {
            for a in 0..3 {
                d_pose[(i, a)] = dp[(i, a)];
                d_pose[(i, 3 + a)] = dw[(i, a)];
                d_n[(i, a)] = dt[(i, a)];
            }
        }
        for (a, d) in dr.iter().enumerate() {
            let dx = p * (d.transpose() * m) * 1e-6;
            d_n[(0, 3 + a)] = dx[0];
            d_n[(1, 3 + a)] = dx[1];
        }
        d_n[(0, 6)] = x.x / x.z;
        d_n[(1, 6)] = x.y / x.z;
    }
}
