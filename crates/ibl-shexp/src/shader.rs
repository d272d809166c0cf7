//! GLSL and HLSL snippets of the reconstruction (Silvennoinen et al. 2025 eq. 11) with a probe's coefficients
//! baked in as constant arrays, ready to paste.
//!
//! The SH basis is emitted as straight-line code generated from the same recurrences as
//! `ibl_core::sh::eval_basis` (associated Legendre in z, C_m/S_m polynomials in x, y). The code
//! is built as a small expression list first, so tests can evaluate exactly what is printed.

use crate::basis::{band_of, coeffs_of_order};
use crate::coeffs::Coeffs;
use std::fmt::Write;

/// An expression of the generated SH code.
#[derive(Clone, Debug)]
pub enum Expr {
    /// A variable (x, y, z or an earlier temporary).
    Var(String),
    /// A constant.
    Const(f64),
    /// a·b.
    Mul(Box<Expr>, Box<Expr>),
    /// a − b.
    Sub(Box<Expr>, Box<Expr>),
    /// a + b.
    Add(Box<Expr>, Box<Expr>),
}

fn var(s: impl Into<String>) -> Expr {
    Expr::Var(s.into())
}
fn mul(a: Expr, b: Expr) -> Expr {
    Expr::Mul(Box::new(a), Box::new(b))
}

/// A float literal both languages accept.
fn lit(v: f64) -> String {
    format!("{v:.9e}")
}

impl Expr {
    fn render(&self) -> String {
        match self {
            Expr::Var(s) => s.clone(),
            Expr::Const(c) => {
                if *c < 0.0 {
                    format!("({})", lit(*c))
                } else {
                    lit(*c)
                }
            }
            Expr::Mul(a, b) => format!("{} * {}", a.render_factor(), b.render_factor()),
            Expr::Sub(a, b) => format!("({} - {})", a.render(), b.render()),
            Expr::Add(a, b) => format!("({} + {})", a.render(), b.render()),
        }
    }

    fn render_factor(&self) -> String {
        match self {
            Expr::Mul(..) => format!("({})", self.render()),
            _ => self.render(),
        }
    }

    /// Evaluates with the given variable lookup (for tests of the emitted code).
    pub fn eval(&self, env: &dyn Fn(&str) -> f64) -> f64 {
        match self {
            Expr::Var(s) => env(s),
            Expr::Const(c) => *c,
            Expr::Mul(a, b) => a.eval(env) * b.eval(env),
            Expr::Sub(a, b) => a.eval(env) - b.eval(env),
            Expr::Add(a, b) => a.eval(env) + b.eval(env),
        }
    }
}

/// Straight-line statements computing `y[i]` (i < (order+1)²) from a unit direction (x, y, z):
/// `(target, expression)` where a target is a temporary name or `y[i]`.
pub(crate) fn sh_statements(order: usize) -> Vec<(String, Expr)> {
    let bands = order + 1;
    let mut st: Vec<(String, Expr)> = Vec::new();
    for m in 0..bands {
        // C_m, S_m (C_0 = 1, S_0 = 0 are folded in).
        if m == 1 {
            st.push(("c1".into(), var("x")));
            st.push(("s1".into(), var("y")));
        } else if m > 1 {
            let (c, s) = (format!("c{}", m - 1), format!("s{}", m - 1));
            st.push((
                format!("c{m}"),
                Expr::Sub(
                    Box::new(mul(var("x"), var(&c))),
                    Box::new(mul(var("y"), var(&s))),
                ),
            ));
            st.push((
                format!("s{m}"),
                Expr::Add(
                    Box::new(mul(var("x"), var(&s))),
                    Box::new(mul(var("y"), var(&c))),
                ),
            ));
        }
        // P̃_m^m = (2m−1)!! is a constant; P̃_l^m by the three-term recurrence.
        let mut pmm = 1.0f64;
        for k in 1..=m {
            pmm *= (2 * k - 1) as f64;
        }
        for l in m..bands {
            let p = if l == m {
                Expr::Const(pmm)
            } else if l == m + 1 {
                mul(Expr::Const((2 * m + 1) as f64 * pmm), var("z"))
            } else {
                let a = (2 * l - 1) as f64 / (l - m) as f64;
                let b = (l + m - 1) as f64 / (l - m) as f64;
                let prev2 = if l - 2 == m {
                    Expr::Const(pmm)
                } else {
                    var(format!("p{}_{m}", l - 2))
                };
                Expr::Sub(
                    Box::new(mul(
                        Expr::Const(a),
                        mul(var("z"), var(format!("p{}_{m}", l - 1))),
                    )),
                    Box::new(mul(Expr::Const(b), prev2)),
                )
            };
            if l > m {
                st.push((format!("p{l}_{m}"), p.clone()));
            }
            let pref = if l == m {
                Expr::Const(pmm)
            } else {
                var(format!("p{l}_{m}"))
            };
            let k = norm_factor(l, m);
            let i0 = l * (l + 1);
            if m == 0 {
                st.push((format!("y[{i0}]"), mul(Expr::Const(k), pref)));
            } else {
                let k2 = std::f64::consts::SQRT_2 * k;
                st.push((
                    format!("y[{}]", i0 + m),
                    mul(mul(Expr::Const(k2), pref.clone()), var(format!("c{m}"))),
                ));
                st.push((
                    format!("y[{}]", i0 - m),
                    mul(mul(Expr::Const(k2), pref), var(format!("s{m}"))),
                ));
            }
        }
    }
    st
}

/// K_l^m = sqrt((2l+1)/(4π) · (l−m)!/(l+m)!) (the same as ibl_core::sh).
fn norm_factor(l: usize, m: usize) -> f64 {
    let mut ratio = 1.0f64;
    for k in (l - m + 1)..=(l + m) {
        ratio /= k as f64;
    }
    ((2 * l + 1) as f64 / (4.0 * std::f64::consts::PI) * ratio).sqrt()
}

#[derive(Clone, Copy, PartialEq)]
enum Lang {
    Glsl,
    Hlsl,
}

fn emit(c: &Coeffs, lang: Lang) -> String {
    let (v3, f) = match lang {
        Lang::Glsl => ("vec3", "float"),
        Lang::Hlsl => ("float3", "float"),
    };
    let np = coeffs_of_order(c.p_order);
    let nq = coeffs_of_order(c.q_order);
    let mut s = String::new();
    let tail = match c.fresnel {
        crate::dfg::FresnelTail::Ratio => "B / (A + B)",
        crate::dfg::FresnelTail::Printed => "B (Silvennoinen et al. 2025 eq. 15 as printed)",
    };
    let _ = writeln!(s, "// SH-exponential glossy reflection probe (Silvennoinen et al. 2025, eq. 11), generated by shexp-fit.");
    let _ = writeln!(s, "// E0(v, n, alpha) = exp(<vMF(alpha) * Y(r), P> + <vMF(alpha) * Y(h_r), Q>), r = 2 dot(n,v) n - v,");
    let _ = writeln!(s, "// h_r = normalize(n + r), vMF_l = exp(-l(l+1) alpha / 2), alpha = GGX alpha = roughness^2.");
    let _ = writeln!(s, "// Y: real orthonormal SH, +z polar axis, index l(l+1)+m, no Condon-Shortley phase (world space).");
    let _ = writeln!(s, "// P order {} ({np} coefficients), Q order {} ({} coefficients, DC dropped); fitted at alpha = {:?}.", c.p_order, c.q_order, nq - 1, c.alphas);
    let _ = writeln!(s, "// Specular: E = E0 * (F0 + (1 - F0) * tail), tail = {tail} of the split-sum DFG table (A, B).");
    let _ = writeln!(s, "// For many probes, replace the constant arrays by uniform/buffer arrays of the same layout.");
    let arr = |name: &str, vals: &[[f32; 3]]| -> String {
        let items: Vec<String> = vals
            .iter()
            .map(|v| {
                format!(
                    "{v3}({}, {}, {})",
                    lit(v[0] as f64),
                    lit(v[1] as f64),
                    lit(v[2] as f64)
                )
            })
            .collect();
        let n = vals.len().max(1);
        let body = if vals.is_empty() {
            format!("{v3}(0.0, 0.0, 0.0)")
        } else {
            items.join(",\n    ")
        };
        match lang {
            Lang::Glsl => format!("const {v3} {name}[{n}] = {v3}[{n}](\n    {body});\n"),
            Lang::Hlsl => format!("static const {v3} {name}[{n}] = {{\n    {body}}};\n"),
        }
    };
    // With alpha knots the arrays hold every knot's set, knot-major, and shexp_e0 lerps them.
    let knots = c.alpha_knots.as_ref();
    match knots {
        None => {
            s.push_str(&arr("SHEXP_P", &c.p));
            s.push_str(&arr("SHEXP_Q", &c.q));
        }
        Some(k) => {
            let _ = writeln!(s, "// Beyond eq. 11: one coefficient set per alpha knot, interpolated linearly in alpha.");
            let vals: Vec<String> = k.alphas.iter().map(|a| lit(*a as f64)).collect();
            let n = k.alphas.len();
            let _ = match lang {
                Lang::Glsl => writeln!(
                    s,
                    "const float SHEXP_KNOTS[{n}] = float[{n}]({});",
                    vals.join(", ")
                ),
                Lang::Hlsl => writeln!(
                    s,
                    "static const float SHEXP_KNOTS[{n}] = {{ {} }};",
                    vals.join(", ")
                ),
            };
            s.push_str(&arr("SHEXP_P", &k.p.concat()));
            s.push_str(&arr("SHEXP_Q", &k.q.concat()));
        }
    }
    for (fname, order) in [("shexp_sh_p", c.p_order), ("shexp_sh_q", c.q_order)] {
        let n = coeffs_of_order(order);
        let _ = writeln!(s, "\nvoid {fname}({v3} d, out {f} y[{n}]) {{");
        let _ = writeln!(s, "    {f} x = d.x; {f} y_ = d.y; {f} z = d.z;");
        for (target, e) in sh_statements(order) {
            let code = rename_y(&e.render());
            if target.starts_with("y[") {
                let _ = writeln!(s, "    {target} = {code};");
            } else {
                let _ = writeln!(s, "    {f} {target} = {code};");
            }
        }
        let _ = writeln!(s, "}}");
    }
    if c.target == crate::coeffs::Target::E0OverAlbedo {
        let _ = writeln!(
            s,
            "\n// NOTE: this probe was fitted on E0 / (A+B); shexp_e0 returns that ratio."
        );
    }
    let _ = writeln!(s, "\n// Base reflectance E0 (F0 = 1) for unit normal n, unit view v (towards the eye), GGX alpha.");
    let _ = writeln!(s, "{v3} shexp_e0({v3} n, {v3} v, {f} alpha) {{");
    let _ = writeln!(s, "    {v3} r = normalize(2.0 * dot(n, v) * n - v);");
    let _ = writeln!(s, "    {v3} hr = normalize(n + r);");
    let _ = writeln!(s, "    {f} yp[{np}];\n    shexp_sh_p(r, yp);");
    let _ = writeln!(s, "    {f} yq[{nq}];\n    shexp_sh_q(hr, yq);");
    let maxo = c.p_order.max(c.q_order);
    let _ = writeln!(s, "    {f} damp[{}];", maxo + 1);
    for l in 0..=maxo {
        let _ = writeln!(
            s,
            "    damp[{l}] = exp({} * alpha);",
            lit(-((l * (l + 1)) as f64) * 0.5)
        );
    }
    let _ = writeln!(s, "    {v3} e = {v3}(0.0, 0.0, 0.0);");
    // Segment and weight of the knots bracketing alpha (as ibl_shexp::basis::knot_weights).
    if let Some(k) = knots {
        let n = k.alphas.len();
        let _ = writeln!(
            s,
            "    {f} a = clamp(alpha, SHEXP_KNOTS[0], SHEXP_KNOTS[{}]);",
            n - 1
        );
        let _ = writeln!(s, "    int seg = 0;");
        let _ = writeln!(
            s,
            "    for (int k = 1; k < {}; ++k) {{ if (a > SHEXP_KNOTS[k]) seg = k; }}",
            n - 1
        );
        let _ = writeln!(
            s,
            "    {f} t = (a - SHEXP_KNOTS[seg]) / (SHEXP_KNOTS[seg + 1] - SHEXP_KNOTS[seg]);"
        );
        let _ = writeln!(
            s,
            "    int bp = seg * {np};\n    int bq = seg * {};",
            nq - 1
        );
    }
    let lerp = match lang {
        Lang::Glsl => "mix",
        Lang::Hlsl => "lerp",
    };
    // Coefficient i of an array with `stride` entries per knot: a constant, or the lerp between
    // the bracketing knots' sets (offset `base`).
    let coef = |name: &str, base: &str, i: usize, stride: usize| match knots {
        None => format!("{name}[{i}]"),
        Some(_) => format!(
            "{lerp}({name}[{base} + {i}], {name}[{base} + {}], t)",
            stride + i
        ),
    };
    for i in 0..np {
        let _ = writeln!(
            s,
            "    e += {} * (damp[{}] * yp[{i}]);",
            coef("SHEXP_P", "bp", i, np),
            band_of(i)
        );
    }
    for i in 1..nq {
        let _ = writeln!(
            s,
            "    e += {} * (damp[{}] * yq[{i}]);",
            coef("SHEXP_Q", "bq", i - 1, nq - 1),
            band_of(i)
        );
    }
    let _ = writeln!(s, "    return exp(e);\n}}");
    let (ab, f0t) = match lang {
        Lang::Glsl => ("vec2", "vec3"),
        Lang::Hlsl => ("float2", "float3"),
    };
    let _ = writeln!(s, "\n// Specular radiance with the Fresnel tail; dfg = (A, B) from the split-sum DFG table at (n.v, roughness).");
    let _ = writeln!(
        s,
        "{v3} shexp_specular({v3} n, {v3} v, {f} roughness, {f0t} f0, {ab} dfg) {{"
    );
    match c.fresnel {
        crate::dfg::FresnelTail::Ratio => {
            let _ = writeln!(s, "    {f} tail = dfg.y / max(dfg.x + dfg.y, 1.0e-6);");
        }
        crate::dfg::FresnelTail::Printed => {
            let _ = writeln!(s, "    {f} tail = dfg.y;");
        }
    }
    match c.target {
        crate::coeffs::Target::E0 => {
            let _ = writeln!(
                s,
                "    return shexp_e0(n, v, roughness * roughness) * (f0 + (1.0 - f0) * tail);\n}}"
            );
        }
        crate::coeffs::Target::E0OverAlbedo => {
            let _ = writeln!(
                s,
                "    // This probe holds E0 / (A + B): multiply the albedo back in."
            );
            let _ = writeln!(s, "    return shexp_e0(n, v, roughness * roughness) * (dfg.x + dfg.y) * (f0 + (1.0 - f0) * tail);\n}}");
        }
    }
    s
}

/// Renames the direction's `y` component (a bare `y` token) to `y_`, leaving `y[..]` alone.
fn rename_y(code: &str) -> String {
    let b = code.as_bytes();
    let mut out = String::with_capacity(code.len() + 8);
    for (i, ch) in code.char_indices() {
        if ch == 'y' {
            let prev_ident = i > 0 && (b[i - 1].is_ascii_alphanumeric() || b[i - 1] == b'_');
            let next = b.get(i + 1).copied();
            let next_ident =
                matches!(next, Some(c) if c.is_ascii_alphanumeric() || c == b'_' || c == b'[');
            if !prev_ident && !next_ident {
                out.push_str("y_");
                continue;
            }
        }
        out.push(ch);
    }
    out
}

/// The GLSL snippet (GLSL ES 3.0 / GLSL 4.x).
pub fn glsl(c: &Coeffs) -> String {
    emit(c, Lang::Glsl)
}

/// The HLSL snippet (SM 5+).
pub fn hlsl(c: &Coeffs) -> String {
    emit(c, Lang::Hlsl)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;
    use ibl_core::sampling::Pcg32;

    fn probe() -> Coeffs {
        Coeffs {
            p: (0..25).map(|i| [0.1 * i as f32, -0.05, 0.01]).collect(),
            q: (0..8).map(|i| [0.02 * i as f32, 0.0, -0.3]).collect(),
            ..Coeffs::zeros(4, 2, vec![0.2, 1.0])
        }
    }

    #[test]
    fn generated_sh_code_matches_the_core_basis() {
        let mut rng = Pcg32::new(8, 8);
        for order in [0usize, 2, 4, 6] {
            let st = sh_statements(order);
            for _ in 0..50 {
                let d = Vec3::new(
                    rng.next_f32() - 0.5,
                    rng.next_f32() - 0.5,
                    rng.next_f32() - 0.5,
                )
                .normalize();
                let mut vars: std::collections::HashMap<String, f64> = [
                    ("x".to_string(), d.x as f64),
                    ("y".to_string(), d.y as f64),
                    ("z".to_string(), d.z as f64),
                ]
                .into();
                for (t, e) in &st {
                    let v = e.eval(&|n| vars[n]);
                    vars.insert(t.clone(), v);
                }
                let mut want = vec![0.0f32; coeffs_of_order(order)];
                ibl_core::sh::eval_basis(d, order + 1, &mut want);
                for (i, w) in want.iter().enumerate() {
                    let got = vars[&format!("y[{i}]")];
                    assert!(
                        (got - *w as f64).abs() < 1e-5,
                        "order {order} y[{i}]: {got} vs {w}"
                    );
                }
            }
        }
    }

    #[test]
    fn snippets_name_every_coefficient() {
        let c = probe();
        for code in [glsl(&c), hlsl(&c)] {
            assert!(code.contains("SHEXP_P[24]") && code.contains("SHEXP_Q[7]"));
            assert!(!code.contains("NaN") && !code.contains("inf"));
            // The direction's y is renamed; the array y[...] is not.
            assert!(code.contains("y_") && code.contains("y[24] ="));
        }
        assert!(hlsl(&c).contains("static const float3 SHEXP_P[25]"));
        assert_eq!(rename_y("(x * y) - y[3] * yq"), "(x * y_) - y[3] * yq");
    }

    /// `probe()` with three α knots; knot 1's DC is 9.
    fn knot_probe() -> Coeffs {
        let mut c = probe();
        let mut p2 = c.p.clone();
        p2[0] = [9.0; 3];
        c.alpha_knots = Some(crate::coeffs::AlphaKnots {
            alphas: vec![0.2, 0.5, 1.0],
            p: vec![c.p.clone(), p2, c.p.clone()],
            q: vec![c.q.clone(); 3],
            residual: 0.0,
        });
        c
    }

    #[test]
    fn knot_snippets_lerp_every_coefficient() {
        let c = knot_probe();
        let g = glsl(&c);
        assert!(g.contains("const float SHEXP_KNOTS[3] = float[3]("));
        assert!(g.contains("const vec3 SHEXP_P[75]") && g.contains("const vec3 SHEXP_Q[24]"));
        assert!(g.contains("mix(SHEXP_P[bp + 24], SHEXP_P[bp + 49], t)"));
        assert!(g.contains("mix(SHEXP_Q[bq + 7], SHEXP_Q[bq + 15], t)"));
        assert!(g.contains("for (int k = 1; k < 2; ++k)"));
        let h = hlsl(&c);
        assert!(h.contains("static const float SHEXP_KNOTS[3] = {"));
        assert!(h.contains("lerp(SHEXP_P[bp + 0], SHEXP_P[bp + 25], t)"));
        // The knot-major layout puts knot 1's DC (9.0) at index 25.
        let after = &g[g.find("SHEXP_P[75]").unwrap()..];
        let items: Vec<&str> = after.split("vec3(").skip(1).take(26).collect();
        assert!(items[25].starts_with("9.000000000e0"), "{}", items[25]);
    }

    #[test]
    fn glsl_snippet_validates_with_naga_when_available() {
        // naga (wgpu's shader translator) parses and validates GLSL; skipped when absent.
        let Ok(out) = std::process::Command::new("naga").arg("--version").output() else {
            eprintln!("naga not found: GLSL validation skipped");
            return;
        };
        if !out.status.success() {
            return;
        }
        let dir = tempfile::tempdir().unwrap();
        for (name, c) in [("probe", probe()), ("knots", knot_probe())] {
            let path = dir.path().join(format!("{name}.frag"));
            let src = format!(
            "#version 450\n{}\nlayout(location = 0) out vec4 o_color;\nvoid main() {{\n    vec3 n = normalize(vec3(0.2, 0.3, 1.0));\n    o_color = vec4(shexp_specular(n, vec3(0.0, 0.0, 1.0), 0.6, vec3(0.04), vec2(0.5, 0.1)), 1.0);\n}}\n",
            glsl(&c)
        );
            std::fs::write(&path, src).unwrap();
            let r = std::process::Command::new("naga")
                .args(["--input-kind", "glsl", "--shader-stage", "frag"])
                .arg(&path)
                .output()
                .unwrap();
            let msg = String::from_utf8_lossy(&r.stderr).to_string()
                + &String::from_utf8_lossy(&r.stdout);
            eprintln!(
                "naga ({name}): {}",
                if r.status.success() {
                    "GLSL snippet validated"
                } else {
                    &msg
                }
            );
            assert!(r.status.success(), "{name}: {msg}");
        }
    }
}
