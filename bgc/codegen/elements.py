"""The constitutive and structural equations of each element kind (the rules of paper
11.2-11.3 in causal form): one function per kind, ``RULES[kind](builder, name, element)``,
each defining its port variables in an equations ``Builder`` according to the causality
SCAP assigned. Adding an element kind means a rule here (and its schema in
``bgc.model``)."""

from __future__ import annotations

import sympy as sp

from bgc import methods
from bgc.codegen.builder import Builder, Dt, State, matmul
from bgc.errors import EquationError
from bgc.graph.expand import AXES
from bgc.model import symbols


def _Se(bld: Builder, name, el):
    b, s, E, F = bld.port(name)
    bld.define(E, el.fields["effort"], name, b)


def _Sf(bld: Builder, name, el):
    b, s, E, F = bld.port(name)
    bld.define(F, s * el.fields["flow"], name, b)


def _storage(bld: Builder, name, el, qname):
    """C (qname 'q') and I (qname 'p'): integral or derivative causality."""
    b, s, E, F = bld.port(name)
    if isinstance(E, sp.MatrixBase):
        return _storage_vector(bld, name, el, qname, b, s, E, F)
    # For C: e = law(q), dq/dt = f.  For I: f = law(p), dp/dt = e.
    out_var, in_var = (E, s * F) if el.kind == "C" else (s * F, E)
    if bld.cg.storage[name] == "integral":
        x, dx = symbols.state(name, qname), symbols.dstate(name, qname)
        if el.law == el.kind:                   # linear: e = q/C, f = p/I
            value = x / el.fields[el.kind]
        elif el.law == "k":
            value = el.fields["k"] * x
        else:
            value = bld.law(el, el.law, **{qname: x})
        bld.define(E if el.kind == "C" else F, value if el.kind == "C" else s * value,
                    name, b)
        bld.define(dx, in_var, name, b)
        label = f"{name}.{qname}".replace("__", ".")   # box__mx -> box.mx.p
        bld.states.append(State(label, x, dx, el.initial, name))
        bld.display[x], bld.display[dx] = label, f"d({label})/dt"
    else:
        v = symbols.algebraic(name, qname)
        if el.law == el.kind:
            value = el.fields[el.kind] * out_var
        elif el.law == "k":
            value = out_var / el.fields["k"]
        else:
            value = bld.invert(el, el.law, out_var, qname)
        bld.define(v, value, name, b)
        bld.display[v] = f"{name}.{qname}"
        bld.dependent[name] = v
        # the storage's other port variable is the time derivative of v
        bld.define(F if el.kind == "C" else E, (s if el.kind == "C" else 1) * Dt(v),
                    name, b)


def _inverse(M: sp.Matrix, name: str, el, key: str) -> sp.Matrix:
    """The inverse of a constant matrix law, or an EquationError at the law's file:line
    where it is singular (an R of 0 used as a conductance, a mass matrix with a zero)."""
    try:
        return M.inv()
    except (ValueError, ZeroDivisionError):      # sympy's NonInvertibleMatrixError
        raise EquationError(f"{el.kind} '{name}': its {key} is a singular matrix, which "
                            "the causality it has needs inverted", key=f"elements.{name}."
                            f"{key}", loc=el.field_locs.get(key, el.loc),
                            hint="give it an invertible matrix (a positive definite one "
                                 "for C, I and R)") from None


def _storage_vector(bld: Builder, name, el, qname, b, s, E, F):
    """A multiport C or I with a matrix law (mass matrix, inertia tensor, stiffness):
    integral causality only, the law inverted numerically once (it is constant)."""
    if bld.cg.storage[name] != "integral":
        raise EquationError(f"multiport {el.kind} '{name}' would need derivative "
                            "causality, which is only supported on scalar bonds",
                            loc=el.loc, key=f"elements.{name}",
                            hint="let it integrate (e.g. a stiff C between it and the "
                                 "element that imposes its flow)")
    d = len(E)
    x = sp.Matrix([symbols.state(name, f"{qname}{AXES[k]}") for k in range(d)])
    dx = sp.Matrix([symbols.dstate(name, f"{qname}{AXES[k]}") for k in range(d)])
    law = el.fields.get(el.law)
    M = law if isinstance(law, sp.MatrixBase) else law * sp.eye(d)
    inverse = (sp.diag(*[1 / M[k, k] for k in range(d)]) if M.is_diagonal()
               else _inverse(M, name, el, el.law))   # a mass, principal moments: by entry
    value = matmul(M, x) if el.law == "k" else matmul(inverse, x)
    if el.kind == "C":
        bld.define(E, value, name, b)
        bld.define(dx, s * F, name, b)
    else:
        bld.define(F, s * value, name, b)
        bld.define(dx, E, name, b)
    label = name.replace("__", ".")
    initial = (el.initial if isinstance(el.initial, sp.MatrixBase)
               else sp.Matrix([el.initial or 0] * d))
    for k in range(d):
        lab = f"{label}.{qname}{AXES[k]}"
        bld.states.append(State(lab, x[k], dx[k], initial[k], name))
        bld.display[x[k]], bld.display[dx[k]] = lab, f"d({lab})/dt"


def _C(bld: Builder, name, el):
    _storage(bld, name, el, "q")


def _I(bld: Builder, name, el):
    _storage(bld, name, el, "p")


def _R(bld: Builder, name, el):
    b, s, E, F = bld.port(name)
    if isinstance(E, sp.MatrixBase):
        R = el.fields["R"]
        R = R if isinstance(R, sp.MatrixBase) else R * sp.eye(len(E))
        if bld.cg.r_form[name] == "resistance":
            bld.define(E, R * (s * F), name, b)
        else:
            bld.define(F, s * _inverse(R, name, el, "R") * E, name, b)
        return
    f = s * F
    if bld.cg.r_form[name] == "resistance":
        if el.law == "R":
            value = el.fields["R"] * f
        elif el.law == "effort":
            value = bld.law(el, "effort", f=f)
        else:
            value = bld.invert(el, "flow", f, "e")
        bld.define(E, value, name, b)
    else:
        if el.law == "R":
            R = el.fields["R"]
            if R == 0:
                raise EquationError(f"R '{name}' is 0 but its causality needs its "
                                    "conductance 1/R", loc=el.field_locs["R"],
                                    key=f"elements.{name}.R",
                                    hint="use a small positive R or remove the element")
            value = E / R
        elif el.law == "flow":
            value = bld.law(el, "flow", e=E)
        else:
            value = bld.invert(el, "effort", E, "f")
        bld.define(F, s * value, name, b)


def _zero(bld: Builder, name, el):
    _junction(bld, name, effort_common=True)


def _one(bld: Builder, name, el):
    _junction(bld, name, effort_common=False)


def _junction(bld: Builder, name, effort_common):
    bonds = bld.g.ports[name]
    sign = {b: (1 if bld.g.points_into(b, name) else -1) for b in bonds}
    # 0: the strong bond brings the effort in; 1: the strong bond brings the flow in.
    strong = [b for b in bonds if bld.cg.receives_effort(b, name) == effort_common][0]
    common, summed = (bld.E, bld.F) if effort_common else (bld.F, bld.E)
    for b in bonds:
        if b != strong:
            bld.define(common(b), common(strong), name, b)
    rest = [_kept(bld, name, b, sign[b] * summed(b)) for b in bonds if b != strong]
    total = sum(rest[1:], rest[0]) if rest else 0 * summed(strong)
    bld.define(summed(strong), -sign[strong] * total, name, strong)


def _kept(bld: Builder, name: str, b: int, term):
    """A bond's term in a junction's sum, less what a scene's junction-activity pass cut
    (``Builder.cut``: the junction no longer feels that effort or flow, while the bond
    still carries the junction's common variable to the other side, a modulated
    source there; ``scene.reduce.junctions``): zero, or zero in the components cut."""
    if not bld.cut:
        return term
    if isinstance(term, sp.MatrixBase):
        return sp.Matrix([0 if (name, b, k) in bld.cut else t for k, t in enumerate(term)])
    return sp.S.Zero if (name, b, None) in bld.cut else term


def _TF(bld: Builder, name, el):
    a, c = bld.g.two_port(name)       # e_a = n e_c, f_c = n f_a
    n = el.fields["ratio"]
    if isinstance(n, sp.MatrixBase):   # f_c = M f_a, e_a = M^T e_c
        n = hoist(bld, name, n)
        if not bld.cg.receives_effort(a, name):
            bld.define(bld.F(c), matmul(n, sp.Matrix([bld.F(a)])), name, c)
            bld.define(bld.E(a), matmul(n.T, sp.Matrix([bld.E(c)])), name, a)
        else:                          # a rotation, or a constant invertible matrix
            inv = n.T if el.orthogonal else _inverse(n, name, el, "ratio")
            bld.define(bld.F(a), matmul(inv, bld.F(c)), name, a)
            bld.define(bld.E(c), matmul(inv.T, bld.E(a)), name, c)
        return
    if bld.cg.receives_effort(a, name):
        bld.define(bld.E(c), bld.E(a) / n, name, c)
        bld.define(bld.F(a), bld.F(c) / n, name, a)
    else:
        bld.define(bld.E(a), n * bld.E(c), name, a)
        bld.define(bld.F(c), n * bld.F(a), name, c)


def _GY(bld: Builder, name, el):
    a, c = bld.g.two_port(name)       # e_a = r f_c, e_c = r f_a
    r = el.fields["r"]
    if bld.cg.receives_effort(a, name):
        bld.define(bld.F(c), bld.E(a) / r, name, c)
        bld.define(bld.F(a), bld.E(c) / r, name, a)
    else:
        bld.define(bld.E(a), r * bld.F(c), name, a)
        bld.define(bld.E(c), r * bld.F(a), name, c)


def _EJS(bld: Builder, name, el):
    """Euler's gyroscopic torque omega x (J omega), omega in the principal body frame."""
    b, s, E, F = bld.port(name)
    w = s * F
    h = sp.Matrix([el.fields["J"][i] * w[i] for i in range(3)])
    bld.define(E, w.cross(h), name, b)


def hoist(bld: Builder, name, M: sp.Matrix) -> sp.Matrix:
    """Give each non-constant entry of a matrix modulus its own assignment, so that
    whatever is built on the modulus (loops, Jacobians) refers to it by name instead
    of copying the expression."""
    def entry(i, j):
        e = M[i, j]
        if e.is_Number or e.is_Symbol:
            return e
        v = symbols.modulus(name, i, j)
        bld.define(v, e, name)
        bld.display[v] = f"{name.replace('__', '.')}.M{i}{j}"
        return v
    return sp.Matrix(M.rows, M.cols, entry)


def _XTF(bld: Builder, name, el):
    """Cross-product TF (rule C2): f_out = f_in x r, e_in = r x e_out."""
    a, c = bld.g.two_port(name)
    r = el.fields["r"]
    bld.define(bld.F(c), bld.F(a).cross(r), name, c)
    bld.define(bld.E(a), r.cross(bld.E(c)), name, a)


def _M0(bld: Builder, name, el):
    """A body of negligible mass: its velocity is an unknown U of the algebraic loop
    closed by the balance of forces, written as ``U = U + e`` (i.e. ``e = 0``), unless the
    constraint method writes it its own way (``ConstraintMethod.massless_body``: a method
    with multipliers makes U a state and its rate an unknown of its constraint block)."""
    b, s, E, F = bld.port(name)
    if methods.get(bld.g.method).massless_body(bld, name, b, s, E, F):
        return
    U = sp.Matrix([symbols.unknown(name, k) for k in range(len(E))])
    bld.define(F, s * U, name, b)
    bld.define(U, U + s * E, name, b)
    for k, u in enumerate(U):
        bld.display[u] = f"{name.replace('__', '.')}.{AXES[k]}"


RULES = {"Se": _Se, "MSe": _Se, "Sf": _Sf, "MSf": _Sf, "C": _C, "I": _I, "R": _R,
         "0": _zero, "1": _one, "TF": _TF, "MTF": _TF, "GY": _GY, "MGY": _GY, "EJS": _EJS,
         "XTF": _XTF, "M0": _M0}
