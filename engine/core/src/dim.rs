//! The dimension the engine is compiled for (docs/architecture.md, "Two and three
//! dimensions"). One source builds twice: the `sph-core` package for 2D and the
//! `sph-core3d` package (`engine/core3d`, the same files with the `dim3` feature) for
//! 3D, as rapier and salva build their 2D and 3D crates. Code written against
//! [`Vector`] and [`DIM`] serves both; what differs (a kernel's normalisation, the
//! extra component of a record) is chosen here or behind `cfg(feature = "dim3")`.
//!
//! Axes in both: x along the tank, y up (gravity is -y), and in 3D z across the tank
//! (its breadth). A 2D scene is the x-y section of the 3D one.

/// The number of space dimensions: 2, or 3 with the `dim3` feature.
#[cfg(not(feature = "dim3"))]
pub const DIM: usize = 2;
/// The number of space dimensions: 2, or 3 with the `dim3` feature.
#[cfg(feature = "dim3")]
pub const DIM: usize = 3;

/// A point or vector of the space: `DVec2`, or `DVec3` with the `dim3` feature.
#[cfg(not(feature = "dim3"))]
pub type Vector = glam::DVec2;
/// A point or vector of the space: `DVec2`, or `DVec3` with the `dim3` feature.
#[cfg(feature = "dim3")]
pub type Vector = glam::DVec3;

/// A point or vector as a scenario file writes it: `(x, y)`, or `(x, y, z)` in 3D
/// (converts to and from [`Vector`] with `into`).
#[cfg(not(feature = "dim3"))]
pub type Coords = (f64, f64);
/// A point or vector as a scenario file writes it: `(x, y)`, or `(x, y, z)` in 3D
/// (converts to and from [`Vector`] with `into`).
#[cfg(feature = "dim3")]
pub type Coords = (f64, f64, f64);

/// `two` in 2D, `three` in 3D: for a constant that differs by dimension (a kernel's
/// normalisation), so both values stand side by side where it is defined.
#[inline(always)]
pub const fn pick(two: f64, three: f64) -> f64 {
    if DIM == 2 {
        two
    } else {
        three
    }
}

/// h^DIM: the length a kernel's normalisation is divided by (W = NORM / h^DIM w(r/h)).
/// In 2D it is `h * h`, the same operation the 2D engine has always done.
#[inline(always)]
pub fn h_pow(h: f64) -> f64 {
    if DIM == 2 {
        h * h
    } else {
        h * h * h
    }
}

/// ds^DIM: the volume of one particle of spacing `ds` on the initial lattice.
#[inline(always)]
pub fn cell_volume(ds: f64) -> f64 {
    h_pow(ds)
}

/// The vector (x, y) of the x-y plane (z = 0 in 3D): the plane a 2D scene is, and the
/// plane a tank rolls in.
#[inline(always)]
pub fn xy(x: f64, y: f64) -> Vector {
    #[cfg(not(feature = "dim3"))]
    return Vector::new(x, y);
    #[cfg(feature = "dim3")]
    return Vector::new(x, y, 0.0);
}

/// `v` turned about the z axis by the angle whose (cos, sin) is `rotation`: the roll
/// of a tank ([`crate::motion::Pose`]); in 3D z is kept.
#[inline(always)]
pub fn rotate_z(rotation: glam::DVec2, v: Vector) -> Vector {
    #[cfg(not(feature = "dim3"))]
    return rotation.rotate(v);
    #[cfg(feature = "dim3")]
    return rotation.rotate(v.truncate()).extend(v.z);
}

/// z x v, the unit z axis crossed with `v`: (-y, x) in 2D (`perp`), (-y, x, 0) in 3D.
/// A rotation's rate omega about z moves the point at r with omega (z x r).
#[inline(always)]
pub fn z_cross(v: Vector) -> Vector {
    #[cfg(not(feature = "dim3"))]
    return v.perp();
    #[cfg(feature = "dim3")]
    return Vector::new(-v.y, v.x, 0.0);
}

/// `v` projected on the x-y plane: itself in 2D, z set to 0 in 3D (the distance from
/// a z axis, for a rotation's centripetal acceleration).
#[inline(always)]
pub fn in_xy(v: Vector) -> Vector {
    #[cfg(not(feature = "dim3"))]
    return v;
    #[cfg(feature = "dim3")]
    return Vector::new(v.x, v.y, 0.0);
}

/// The z component of a x b: `perp_dot` in 2D, (a x b).z in 3D (a moment about a z
/// axis).
#[inline(always)]
pub fn cross_z(a: Vector, b: Vector) -> f64 {
    a.x * b.y - a.y * b.x
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The feature and the vector type agree: DIM components, and h^DIM by hand.
    #[test]
    fn the_dimension_is_the_vectors() {
        assert_eq!(Vector::ZERO.to_array().len(), DIM);
        let h = 0.3_f64;
        let expected = if cfg!(feature = "dim3") {
            h * h * h
        } else {
            h * h
        };
        assert_eq!(h_pow(h), expected);
        assert_eq!(cell_volume(h), expected);
        assert_eq!(pick(2.0, 3.0), DIM as f64);
    }

    /// The plane helpers: a quarter turn about z takes x to y and y to -x (z kept),
    /// z x v is that turn of v's in-plane part, and the projection drops z.
    #[test]
    fn turns_about_z_act_in_the_x_y_plane() {
        let quarter = glam::DVec2::new(0.0, 1.0);
        assert_eq!(rotate_z(quarter, xy(1.0, 0.0)), xy(0.0, 1.0));
        assert_eq!(rotate_z(quarter, xy(0.0, 2.0)), xy(-2.0, 0.0));
        assert_eq!(z_cross(xy(3.0, 4.0)), xy(-4.0, 3.0));
        assert_eq!(in_xy(xy(3.0, 4.0)), xy(3.0, 4.0));
        // (1, 2) x (3, 5) = 1 5 - 2 3; x x y = 1, y x x = -1.
        assert_eq!(cross_z(xy(1.0, 2.0), xy(3.0, 5.0)), -1.0);
        assert_eq!(cross_z(xy(1.0, 0.0), xy(0.0, 1.0)), 1.0);
        assert_eq!(cross_z(xy(0.0, 1.0), xy(1.0, 0.0)), -1.0);
        assert_eq!(cross_z(xy(2.0, 0.0), xy(0.0, 3.0)), 6.0);
        #[cfg(feature = "dim3")]
        {
            let v = Vector::new(1.0, 2.0, 5.0);
            assert_eq!(rotate_z(quarter, v), Vector::new(-2.0, 1.0, 5.0));
            assert_eq!(z_cross(v), Vector::new(-2.0, 1.0, 0.0));
            assert_eq!(in_xy(v), Vector::new(1.0, 2.0, 0.0));
        }
    }
}
