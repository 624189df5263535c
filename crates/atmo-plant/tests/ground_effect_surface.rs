//! The ground-effect component returns the surface documented in
//! docs/ground_effect.md, and that surface has the shape the paper reports.

use atmo_core::ground_effect::table::{GroundEffect, GroundEffectConfig, cheeseman_bennett};

const DOC: &str = include_str!("../../../docs/ground_effect.md");

/// (tilt deg, height m, mean %, std %) for every cell of the documented table.
fn documented_cells() -> Vec<(f64, f64, f64, f64)> {
    let start = DOC
        .find("<!-- surface-table: begin -->")
        .expect("table start marker");
    let end = DOC
        .find("<!-- surface-table: end -->")
        .expect("table end marker");
    let mut lines = DOC[start..end].lines().filter(|l| l.starts_with('|'));
    let header: Vec<f64> = lines
        .next()
        .expect("a header row")
        .split('|')
        .skip(2)
        .filter(|c| !c.trim().is_empty())
        .map(|c| c.trim().parse().expect("a height in the header"))
        .collect();
    let mut cells = Vec::new();
    for line in lines.skip(1) {
        let cols: Vec<&str> = line
            .split('|')
            .map(str::trim)
            .filter(|c| !c.is_empty())
            .collect();
        let tilt: f64 = cols[0].parse().expect("a tilt in the first column");
        for (h, cell) in header.iter().zip(&cols[1..]) {
            let (mean, std) = cell.split_once('±').expect("a cell 'mean ± std'");
            cells.push((
                tilt,
                *h,
                mean.trim().parse().expect("a mean"),
                std.trim().parse().expect("a standard deviation"),
            ));
        }
    }
    cells
}

#[test]
fn the_component_returns_the_documented_surface() {
    let surface = GroundEffect::default_surface();
    let cells = documented_cells();
    assert_eq!(cells.len(), 12 * 8, "the whole table was read");
    for (tilt, h, mean, std) in cells {
        let g = surface.gain(h, tilt.to_radians());
        // The document rounds to 0.01 %.
        assert!(
            (100.0 * g.mean - mean).abs() <= 0.005 + 1e-9,
            "mean at {tilt} deg, {h} m: {} vs {mean}",
            100.0 * g.mean
        );
        assert!(
            (100.0 * g.std - std).abs() <= 0.005 + 1e-9,
            "std at {tilt} deg, {h} m: {} vs {std}",
            100.0 * g.std
        );
    }
}

#[test]
fn the_surface_has_the_shape_of_the_papers_fig_3c() {
    let s = GroundEffect::default_surface();
    let g = |h: f64, deg: f64| s.gain(h, deg.to_radians());
    // Largest at 50 deg: almost +20 % at the lowest measured height.
    let peak = g(0.25, 50.0).mean;
    assert!((0.17..0.20).contains(&peak), "{peak}");
    for deg in [40.0, 45.0, 55.0, 60.0, 65.0, 70.0] {
        assert!(g(0.25, deg).mean < peak, "{deg} deg");
    }
    // Clearly positive at 40 and 60 deg.
    for deg in [40.0, 60.0] {
        assert!(
            g(0.25, deg).mean > 0.05 && g(0.45, deg).mean > 0.02,
            "{deg} deg"
        );
    }
    // Gone by about 0.7 m at every tilt of the table.
    for deg in [40.0, 50.0, 60.0, 70.0] {
        assert!(
            g(0.72, deg).mean.abs() < 1e-12 && g(0.9, deg).mean.abs() < 1e-12,
            "{deg} deg"
        );
        // And decaying monotonically with height.
        let mut last = f64::INFINITY;
        for k in 0..=47 {
            let h = 0.25 + 0.01 * f64::from(k);
            let v = g(h, deg).mean.abs();
            assert!(v <= last + 1e-15, "{deg} deg at {h} m");
            last = v;
        }
    }
    // Suction at 70 deg, fluctuating down to 85 % within one standard deviation.
    let suction = g(0.25, 70.0);
    assert!(suction.mean < -0.03);
    assert!(
        (1.0 + suction.mean - suction.std - 0.85).abs() < 1e-9,
        "{suction:?}"
    );
    // Below 40 deg the classical law: exactly Cheeseman-Bennett up to 30 deg.
    for h in [0.15, 0.25, 0.5] {
        assert_eq!(g(h, 0.0).mean, cheeseman_bennett(0.11, h));
        assert_eq!(g(h, 0.0).std, 0.0);
        let tilted = 25.0_f64.to_radians();
        assert!((g(h, 25.0).mean - cheeseman_bennett(0.11, h / tilted.cos())).abs() < 1e-15);
    }
    // Continuous across the blend (30 -> 40 deg) and the table's rows.
    for deg10 in 0..900 {
        let deg = f64::from(deg10) / 10.0;
        let a = g(0.3, deg).mean;
        let b = g(0.3, deg + 0.1).mean;
        assert!((a - b).abs() < 0.012, "jump at {deg} deg: {a} -> {b}");
    }
}

#[test]
fn cheeseman_bennett_is_the_classical_image_law() {
    // T / T_inf = 1 / (1 - (R / 4z)^2): +1.6 % at z = 2R, +6.7 % at z = R.
    assert!((cheeseman_bennett(1.0, 2.0) - (1.0 / (1.0 - 1.0 / 64.0) - 1.0)).abs() < 1e-15);
    assert!((cheeseman_bennett(1.0, 1.0) - (16.0 / 15.0 - 1.0)).abs() < 1e-15);
    // Held at z = R / 2 closer in (the law diverges at R / 4).
    assert_eq!(cheeseman_bennett(1.0, 0.3), cheeseman_bennett(1.0, 0.5));
}

#[test]
fn a_custom_table_is_used_as_given() {
    let mut cfg = GroundEffectConfig::default();
    cfg.gain[1][0] = 0.30;
    let s = GroundEffect::new(&cfg);
    assert!((s.gain(0.25, 50f64.to_radians()).mean - 0.30).abs() < 1e-15);
}

/// The controller's model linearizes the mean surface: its partials are the
/// exact derivatives of the piece that holds the point (checked by central
/// differences away from the table's kinks), and its value is the plant's mean.
#[test]
fn mean_partials_match_finite_differences() {
    let ge = GroundEffect::default_surface();
    let eps = 1e-7;
    // (h m, varphi deg): classical, blend, table, beyond the table's heights.
    let points = [
        (0.4, 10.0),
        (0.3, 25.0),
        (0.3, 33.0),
        (0.3, 37.0),
        (0.3, 44.0),
        (0.4, 52.0),
        (0.5, 63.0),
        (0.28, 67.0),
        (0.6, 58.0),
        (0.2, 55.0),
        (0.9, 45.0),
    ];
    for (h, deg) in points {
        let deg: f64 = deg;
        let v = deg.to_radians();
        let p = ge.mean_with_partials(h, v);
        assert!((p.gain - ge.gain(h, v).mean).abs() < 1e-15, "({h}, {deg})");
        let dh = (ge.gain(h + eps, v).mean - ge.gain(h - eps, v).mean) / (2.0 * eps);
        let dv = (ge.gain(h, v + eps).mean - ge.gain(h, v - eps).mean) / (2.0 * eps);
        assert!(
            (p.d_height - dh).abs() < 1e-6,
            "dg/dh at ({h}, {deg}): {} vs {dh}",
            p.d_height
        );
        assert!(
            (p.d_tilt - dv).abs() < 1e-6,
            "dg/dvarphi at ({h}, {deg}): {} vs {dv}",
            p.d_tilt
        );
    }
    // Something to check: the surface is not flat at the landing's heights.
    assert!(ge.mean_with_partials(0.3, 50f64.to_radians()).d_height < -0.5);
}

/// The Monte Carlo's plant surface: the table scaled, the tilt axis shifted.
#[test]
fn perturbed_surface_is_scaled_and_shifted() {
    let ge = GroundEffect::default_surface();
    let shift = 3f64.to_radians();
    let other = GroundEffect::new(&GroundEffectConfig::default().perturbed(1.2, 3.0));
    for (h, deg) in [(0.3, 50.0f64), (0.5, 60.0), (0.25, 68.0)] {
        let v: f64 = deg.to_radians();
        let want = 1.2 * ge.gain(h, v).mean;
        assert!(
            (other.gain(h, v + shift).mean - want).abs() < 1e-12,
            "({h}, {deg})"
        );
    }
}
