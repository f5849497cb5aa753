//! (temporary shim; replaced by the measured implementation on branch `signal`)
#![allow(missing_docs)]
pub fn sin(x: f32) -> f32 {
    libm::sinf(x)
}
pub fn cos(x: f32) -> f32 {
    libm::cosf(x)
}
pub fn sin_cos(x: f32) -> (f32, f32) {
    (libm::sinf(x), libm::cosf(x))
}
pub fn tan(x: f32) -> f32 {
    libm::tanf(x)
}
pub fn atan(x: f32) -> f32 {
    libm::atanf(x)
}
pub fn atan2(y: f32, x: f32) -> f32 {
    libm::atan2f(y, x)
}
pub fn sqrt(x: f32) -> f32 {
    libm::sqrtf(x)
}
pub fn hypot(x: f32, y: f32) -> f32 {
    libm::hypotf(x, y)
}
pub fn wrap_pi(x: f32) -> f32 {
    let t = core::f32::consts::TAU;
    x - t * libm::floorf((x + core::f32::consts::PI) / t)
}
