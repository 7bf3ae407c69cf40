"""Stage **kernels**: an EquationSystem's run-time work as LLVM IR; this module assembles it.

numba's compile time for one straight-line function grows faster than its length (the
SARIB's Jacobian: minutes); LLVM, given the same operations as IR, compiles them in about a
second. So everything a generated module computes is IR, compiled through llvmlite (the
LLVM binding numba itself uses) when the module is first imported on a machine; numba only
wraps it (``rhs``, ``jac``, ... stay numba functions a script can call or inline).

The stage in parts, each a module:
- ``workspace``: the workspace ``w`` (``Layout``: a slot per assigned symbol, a region per
  linear block, ``Block``) and each block's solve chosen;
- ``steps``: a program's work as typed steps (``Set``, ``Store``, ``Solve``, ``Out``,
  ``Grad``, ...), which ``instances`` may group into loops over a component's instances;
- ``lowering``: sympy expressions to IR values, one method per node kind, and their
  partials by reverse mode (``Function``);
- ``linalg``: the linear-algebra kernels (the Jacobian's tape, dense and sparse LU,
  least squares, a constraint block's ``A = -K B``: IR templates rendered by Jinja,
  ``templates/*.ll.j2``) and each linear block's functions;
- here, the assembly (``Module``, ``lower``):

- **Programs**: ``rhs``, ``jac`` (its run-time partials), ``out``, ``guard``, ``con``:
  each its cone of assignments in causal order, in functions of at most ``CHUNK`` steps
  and about ``CHUNK_OPS`` instructions (LLVM's cost stays linear in the model's size).
  Values cross functions through the workspace; within a function they stay in
  registers. These chunks are a module of their own (``Kernels.ir_straight``), given only
  local passes.
- **Linear blocks** (algebraic loops, constraint blocks) are solved where the causal
  order reaches them, each by a function of its own (``@<prefix>_block<index>``): on the
  block's structure by sparse LU with static pivots (``bgc.codegen.elimination``'s plan,
  a loop over constant tables) where that pays, else (or where the pivots grow) LU with
  partial pivoting, or, where the constraints' rank at run time is below the block's
  size, least squares through LAPACK's SVD (scipy's dgesdd). A constraint block
  ``A = -K B`` is formed from K's and B's non-zeros only.
- **The Jacobian**: each assignment's partials by reverse-mode differentiation of its
  expression tree (``lowering.Function.grad``: no symbolic derivative is ever formed),
  then the compressed forward-mode tape of ``bgc.codegen.jacobian`` as a loop over
  constant tables.
- **C entry points** ``void f(double t, double *x, double *p, double *out)`` for bgc's
  native integrators and the module's functions that bgc calls from Python now and then
  (``constraints``, ``guards``, ``project``, ``outputs_at``'s loop ``out_at``: through
  ctypes, no numba wrapper to compile).

The IR is plain text, target-independent (no triple, no CPU), with every number written
exactly (hexadecimal doubles): the same model gives the same bytes on every machine. A
generated module keeps the integer tables apart (``lower(data=True)``): external in the
IR, their values numpy arrays of the module's own, given to LLVM by address.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from bgc.codegen import instances, linalg
from bgc.codegen.equations import LinearBlock
from bgc.codegen.linalg import MEMCPY, MEMSET
from bgc.codegen.lowering import ARGS, DBL, Function, double
from bgc.codegen.steps import Grad, LoopOver, Out, Set, Solve, Store, Zero, program_steps
from bgc.codegen.workspace import Block, Layout

# the functions' prefix while the IR is built (emit replaces it by the module's own)
PLACEHOLDER = "bgc_kernel_prefix"
CHUNK = 300          # assignments (or stores) per IR function
# at most about this many instructions a function: LLVM's passes cost more than linearly
# in a function's size, and a zcp chain's eliminated expressions make a few assignments
# long
CHUNK_OPS = 2000
# LLVM's IR passes at -O1 and instruction selection at -O0 (fast, local register
# allocation): on the SARIB's lagrange module 1 s instead of 11 s at -O2/-O2, and the
# rhs and Jacobian run as fast as numba's -O3 build of the same code did. The loops'
# module (tape, solves, drivers: 1 % of IFToMM A02's IR at N = 40) at -O2: its code
# generation 0.05 -> 0.3 s there (the straight-line chunks' would take 18 s), and the
# rhs under method augmented, whose block's L D L^T is most of it, 1.6x faster
IR_OPT, CODEGEN_OPT, LOOPS_CODEGEN_OPT = 1, 0, 2
# The straight-line chunks (most of the IR) take only local passes: -O1's loop passes
# find nothing in them and cost half the IR passes' time (loop vectorization alone 14 %
# on a 40-link zcp chain), while the rhs runs within a few per cent of -O1's. The loops
# (tape, solves) keep -O1 with its module passes: without them the Jacobian is 3x slower.
STRAIGHT_PASSES = ("instruction_combine", "simplify_cfg", "dead_code_elimination")


@dataclass
class Kernels:
    """The IR and what the numba side needs to know of it: the workspace size, the
    linear blocks (in the order of the solver's tables) and the tables' slots. The IR is
    two modules, compiled with different passes and linked: ``ir`` (the loops: the
    Jacobian's tape, the linear solves, the programs' drivers and entry points; -O1) and
    ``ir_straight`` (the programs' straight-line chunks; a few local passes)."""
    ir: str
    ir_straight: str
    n_work: int         # the Jacobian's workspace
    n_eval: int         # the other programs' (its first n_eval slots)
    n_schur: int        # ``jac_schur``'s (the Jacobian's and its scratch; 0: none)
    blocks: list[Block]
    # ``lower(data=True)``: the integer tables (name -> values; ``<prefix>_<name>`` in the
    # IR, external there), which the module defines itself
    data: dict | None = None


class Module(linalg.LinearBlocks):
    """The IR module: chunk functions, one function per program, the Jacobian's tape,
    the linear blocks' functions (``linalg.LinearBlocks``) and the C entry points of the
    native integrators."""

    def __init__(self, prefix: str, system, layout: Layout, memo: dict | None = None,
                 data: dict | None = None):
        self.prefix, self.layout = prefix, layout
        # where given, the integer tables' values go here (name -> values) and the IR
        # declares them external (a generated module hands them over as numpy arrays)
        self.data = data
        self.states = {st.sym: i for i, st in enumerate(system.states)}
        self.params = {s: i for i, (s, _, _) in enumerate(system.params)}
        self.decls: set[str] = set()
        self.functions: list[str] = []
        self.straight: list[str] = []       # the programs' chunks (their own module)
        self.globals: list[str] = []
        self.instances = system.model.instances if system.model else {}
        self.loops = 0
        self.assigned = {it[1]: it[0] for it in system.assignments
                         if not isinstance(it, LinearBlock)} if self.instances else {}
        # instances.schedule's, shared by the programs (and with emit.programs' cones)
        self.memo: dict = {} if memo is None else memo

    @staticmethod
    def _region(fn: Function, offset: int, base: str = "%w") -> str:
        """An i8* to base[offset] (for memset and memcpy)."""
        return fn.op(f"bitcast double* {fn.ptr(base, offset)} to i8*")

    def zero(self, fn: Function, base: str, offset: int, count: int):
        if count:
            self.decls.add(MEMSET)
            fn.body.append(f"  call void @llvm.memset.p0i8.i64(i8* "
                           f"{self._region(fn, offset, base)}, i8 0, i64 {8 * count}, i1 false)")

    def copy(self, fn: Function, to: int, frm: int, count: int):
        if count:
            self.decls.add(MEMCPY)
            fn.body.append(f"  call void @llvm.memcpy.p0i8.p0i8.i64(i8* "
                           f"{self._region(fn, to)}, i8* {self._region(fn, frm)}, "
                           f"i64 {8 * count}, i1 false)")
    def program(self, name: str, items, outputs, after: str | None = None):
        """``@<prefix>_<name>(t, x, p, w, out)``: the assignments in chunks, each linear
        block solved where the causal order reaches it; ``after``: a program called
        first, whose values in w the steps read (its own outputs into the layout's
        ``scratch``)."""
        chunks: list[str] = []       # calls, in order
        fn = None
        count = 0

        def flush():
            nonlocal fn, count
            if fn is not None and (fn.body or not chunks):
                self.straight.append(fn.text(linkage=""))
                chunks.append(f"  call void @{fn.name}(double %t, double* %x, double* %p, "
                              f"double* %w, double* %out)")
            fn = Function(f"{self.prefix}_{name}_{len(chunks)}", self.layout, self.states,
                           self.params, self.decls)
            count = 0

        flush()
        for step in instances.schedule(list(program_steps(items, outputs, self.layout)),
                                       self.instances, self.where, self.assigned,
                                       memo=self.memo):
            if isinstance(step, LoopOver):  # instances of one part: a loop (instances.py)
                flush()
                chunks.append(self.loop(name, step.loop))
                continue
            if isinstance(step, Solve):
                blk = self.layout.blocks[step.index]
                self.solve(fn, blk, blk.b, blk.columns, True)
                self.copy(fn, blk.u, blk.b, blk.n * blk.columns)
                flush()                 # what follows reads the unknowns from w
                continue
            if count >= CHUNK or fn.n >= CHUNK_OPS:
                flush()
            count += 1
            self.lower_step(fn, step)
        flush()
        if after is not None:           # (it computes the tables' values too)
            chunks[:0] = [f"  %scratch = getelementptr inbounds double, double* %w, i64 "
                          f"{self.layout.scratch}",
                          f"  call void @{self.prefix}_{after}(double %t, double* %x, "
                          f"double* %p, double* %w, double* %scratch)"]
        elif self.layout.tables:
            chunks.insert(0, f"  call void @{self.prefix}_tables(double %t, double* %w)")
        self.functions.append("\n".join(
            [f"define void @{self.prefix}_{name}({ARGS}) nounwind {{", "entry:", *chunks,
             "  ret void", "}"]))

    def lower_step(self, fn: Function, step):
        """One straight-line step into ``fn``."""
        if isinstance(step, Set):
            fn.assign(step.v, step.e)
        elif isinstance(step, Store):
            fn.store("%w", step.slot, fn.val(step.e))
        elif isinstance(step, Out):
            fn.store("%out", step.slot, fn.val(step.e))
        elif isinstance(step, Grad):
            d = fn.grad(step.e, [w for _, w in step.partials])
            for slot, w in step.partials:
                fn.store("%out", slot, d[w])
        elif isinstance(step, Zero):
            self.zero(fn, "%w", step.at, step.count)
        else:
            raise TypeError(f"internal: no code for the step {step!r}")

    def where(self, s) -> tuple[str, int]:
        """Where a symbol's value is: ("x", state), ("p", parameter) or ("w", slot)."""
        if s in self.states:
            return "x", self.states[s]
        if s in self.params:
            return "p", self.params[s]
        return "w", self.layout.slot[s]

    def loop(self, name: str, lp) -> str:
        """A loop over instances (``instances.Loop``): its template in the straight
        module, its driver and tables here; returns the program's call of it."""
        k, P = self.loops, self.prefix
        self.loops += 1
        template = f"{P}_{name}_tmpl{k}"
        self.straight.append(instances.template_ir(lp, template, self.layout, self.decls))
        width = max(len(lp.bases), 1)
        rows = self.array(f"{name}_rows{k}", "i64",
                          [x for r in lp.rows for x in (r or [0])])
        nc = len(lp.constants)
        consts = self.array(f"{name}_consts{k}", DBL, [x for r in lp.consts for x in r])
        self.functions.append(instances.driver_ir(f"{P}_{name}_loop{k}", template,
                                                  len(lp.rows), width, rows, (consts, nc),
                                                  ARGS))
        return (f"  call void @{P}_{name}_loop{k}(double %t, double* %x, double* %p, "
                f"double* %w, double* %out)")

    def tables(self, tables):
        """``@<prefix>_tables(t, w)``: each table's value and slope at t into w."""
        if not tables:
            return
        body = []
        for tb in tables:
            value, slope = self.layout.tables[tb.index]
            tt = self.array(f"table_t{tb.index}", DBL, tb.t)
            yy = self.array(f"table_y{tb.index}", DBL, tb.y)
            for at, flag in ((value, "false"), (slope, "true")):
                body += [f"  %v{at} = call double @{self.prefix}_interp(double %t, {tt}, "
                         f"{yy}, i64 {len(tb.t)}, i1 {flag})",
                         f"  %p{at} = getelementptr inbounds double, double* %w, i64 {at}",
                         f"  store double %v{at}, double* %p{at}, align 8"]
        self.functions.append("\n".join(
            [f"define internal void @{self.prefix}_tables(double %t, double* %w) nounwind {{",
             "entry:", *body, "  ret void", "}"]))

    def array(self, name: str, kind: str, values) -> str:
        """A constant global array; returns a pointer to its first element. An integer
        one is external where ``data`` is kept (its values there)."""
        values = list(values) or [0]
        n = len(values)
        if self.data is not None and kind == "i64":
            self.data[name] = [int(v) for v in values]
            self.globals.append(f"@{self.prefix}_{name} = external constant [{n} x {kind}]")
        else:
            text = map(double, values) if kind == DBL else map(str, map(int, values))
            items = f"{kind} " + f", {kind} ".join(text)
            self.globals.append(f"@{self.prefix}_{name} = internal constant [{n} x {kind}] "
                                f"[{items}]")
        return (f"{kind}* getelementptr inbounds ([{n} x {kind}], [{n} x {kind}]* "
                f"@{self.prefix}_{name}, i64 0, i64 0)")

    def jacobian(self, jt, n: int):
        """The Jacobian from the run-time partials (program jac) and the tape through
        them (``@<prefix>_jac_tape(t, x, p, w)``), in two forms: ``@<prefix>_jac_full(t,
        x, p, w, J)``, J dense (N x N, N = n + the open blocks' unknowns) scattered from
        the tape's compressed rows, each open block's -A from its matrix; and
        ``@<prefix>_jac_vals(t, x, p, w, V)``, the same entries as values in the order of
        the pattern (``JAC_I``, ``JAC_J``): what the native integrator's sparse LU reads,
        whose cost follows the non-zeros (a dense N x N is 20 MB for IFToMM A02 at N = 40
        under method augmented, and writing it cost most of a Jacobian)."""
        P, lay = self.prefix, self.layout
        na = n + (jt.n_aug or 0)
        nc = jt.n_colours
        ptr = self.array("tape_ptr", "i64", jt.ptr)
        src = self.array("tape_src", "i64", jt.src)
        fn = Function(f"{P}_jac_tape", lay, {}, {}, self.decls)
        pv, d = fn.ptr("%w", lay.pv), fn.ptr("%w", lay.d)
        fn.body.append(f"  call void @{P}_jac(double %t, double* %x, double* %p, "
                       f"double* %w, double* {pv})")
        self.zero(fn, "%w", lay.d, jt.n_rows * nc)
        for seg in jt.segments:
            if seg[0] == "tape":
                fn.body.append(f"  call void @{P}_tape(double* {d}, double* {pv}, "
                               f"i64 {seg[1]}, i64 {seg[2]}, i64 {nc}, {ptr}, {src})")
            else:                        # u's rows: A^-1 R, R in the rows before them
                b = seg[1]
                blk = lay.blocks[b.index]
                self.copy(fn, lay.d + (b.start + b.n) * nc, lay.d + b.start * nc, b.n * nc)
                self.solve(fn, blk, lay.d + (b.start + b.n) * nc, nc, False)
        self.functions.append(linalg.tape_ir(P))
        self.functions.append(fn.text().replace(", double* noalias %out", "", 1))
        # the entries: from the tape's rows (k: their place in the pattern), and the open
        # blocks' rows on their own unknowns, -A (as regularized when formed)
        tape_at = [k for k, e in enumerate(jt.pattern) if e[2] >= 0]
        a_src, a_at = [], []
        for index, _, m, at in jt.opened or ():
            blk = lay.blocks[index]
            for k, (i, j, r) in enumerate(jt.pattern):
                if r < 0 and at <= i < at + m:
                    a_src.append(blk.a + (blk.a_slot[(i - at, j - at)] if blk.packed
                                          else (i - at) * m + (j - at)))
                    a_at.append(k)
        if a_src:
            self.functions.append(linalg.negate_ir(P))
        tables = {k: self.array(k, "i64", v) for k, v in (
            ("jac_row", [jt.pattern[k][2] for k in tape_at]),
            ("jac_col", [jt.colours[jt.pattern[k][1]] for k in tape_at]),
            ("jac_zero", [0] * len(tape_at)), ("jac_k", tape_at),
            ("jac_i", [jt.pattern[k][0] for k in tape_at]),
            ("jac_j", [jt.pattern[k][1] for k in tape_at]))}
        for name, dense in (("jac_full", True), ("jac_vals", False)):
            fn = Function(f"{P}_{name}", lay, {}, {}, self.decls)
            d = fn.ptr("%w", lay.d)
            fn.body.append(f"  call void @{P}_jac_tape(double %t, double* %x, double* %p, "
                           "double* %w)")
            if dense:               # J[i, j]: row i's offset i * na (zeroed first)
                self.zero(fn, "%J", 0, na * na)
                rows, cols, stride = tables["jac_i"], tables["jac_j"], na
            else:                   # V[k]: "row" 0, "column" k
                rows, cols, stride = tables["jac_zero"], tables["jac_k"], 0
            fn.body.append(f"  call void @{P}_scatter(double* %J, double* {d}, "
                           f"i64 {len(tape_at)}, i64 {stride}, i64 {nc}, {rows}, {cols}, "
                           f"{tables['jac_row']}, {tables['jac_col']})")
            if a_src:
                dst = [jt.pattern[k][0] * na + jt.pattern[k][1] for k in a_at] if dense \
                    else a_at
                fn.body.append(
                    f"  call void @{P}_negate(double* %J, double* %w, i64 {len(a_src)}, "
                    f"{self.array(f'{name}_a_src', 'i64', a_src)}, "
                    f"{self.array(f'{name}_a_dst', 'i64', dst)})")
            self.functions.append(fn.text(linkage="")
                                  .replace("double* noalias %out", "double* noalias %J", 1))
        if jt.n_aug:            # the model's own Jacobian, from the open one
            self.functions.append(linalg.schur_ir(P, n, jt.n_aug, lay.size))

    def entry(self, name: str, program: str, n_work: int):
        """``@<prefix>_<name>(t, x, p, out)``: a C entry point (the native integrators',
        with a workspace of its own (malloc'ed: the SARIB's is ~100 kB, too large for a
        stack)."""
        self.decls |= {"declare i8* @malloc(i64)", "declare void @free(i8*)"}
        size = 8 * max(n_work, 1)
        self.functions.append("\n".join([
            f"define void @{self.prefix}_{name}(double %t, double* %x, double* %p, "
            f"double* %out) nounwind {{",
            "entry:",
            f"  %raw = call i8* @malloc(i64 {size})",
            "  %w = bitcast i8* %raw to double*",
            f"  call void @{self.prefix}_{program}(double %t, double* %x, double* %p, "
            f"double* %w, double* %out)",
            "  call void @free(i8* %raw)",
            "  ret void", "}"]))

    def entry_at(self, n: int, n_out: int, n_work: int):
        """``@<prefix>_out_at(t, X, k, p, Y)``: program out at the ``k`` instants
        ``t[i]``, ``X[i, :]`` into ``Y[i, :]`` (row-major), one workspace for them all: a
        run's outputs in one call from Python (``outputs_at``), the loop here."""
        self.decls |= {"declare i8* @malloc(i64)", "declare void @free(i8*)"}
        P = self.prefix
        self.functions.append("\n".join([
            f"define void @{P}_out_at(double* %t, double* %X, i64 %k, double* %p, "
            f"double* %Y) nounwind {{",
            "entry:",
            f"  %raw = call i8* @malloc(i64 {8 * max(n_work, 1)})",
            "  %w = bitcast i8* %raw to double*",
            "  br label %head",
            "head:",
            "  %i = phi i64 [0, %entry], [%next, %body]",
            "  %more = icmp slt i64 %i, %k",
            "  br i1 %more, label %body, label %exit",
            "body:",
            "  %ti = getelementptr inbounds double, double* %t, i64 %i",
            "  %tv = load double, double* %ti, align 8",
            f"  %xo = mul i64 %i, {n}",
            "  %xi = getelementptr inbounds double, double* %X, i64 %xo",
            f"  %yo = mul i64 %i, {n_out}",
            "  %yi = getelementptr inbounds double, double* %Y, i64 %yo",
            f"  call void @{P}_out(double %tv, double* %xi, double* %p, double* %w, "
            "double* %yi)",
            "  %next = add i64 %i, 1",
            "  br label %head",
            "exit:",
            "  call void @free(i8* %raw)",
            "  ret void", "}"]))

    def text(self) -> str:
        """The loops' module: it declares the chunks it calls."""
        return "\n\n".join(sorted(self.decls) + self.globals + self.functions
                           + [_declaration(f) for f in self.straight]) + "\n"

    def straight_text(self) -> str:
        """The chunks' module: it declares what the other module defines with external
        linkage (among it the solves the chunks call)."""
        shared = [_declaration(f) for f in self.functions if not _DEFINE.search(f).group(1)]
        return "\n\n".join(sorted(self.decls) + shared + self.straight) + "\n"


_DEFINE = re.compile(r"^define (internal )?(\w+) @(\w+)\(([^)]*)\)", re.M)


def _declaration(definition: str) -> str:
    """``declare ...`` for the function that ``definition`` defines (no attributes)."""
    m = _DEFINE.search(definition)
    return f"declare {m.group(2)} @{m.group(3)}({m.group(4)})"


# the programs a module has (``proj``: method augmented's projection, where it has one),
# and the C entry points of the native integrators
PROGRAMS = ("rhs", "jac", "out", "guard", "con", "proj")
ENTRIES = (("rhs_entry", "rhs"), ("jac_entry", "jac_full"), ("guard_entry", "guard"),
           ("proj_entry", "proj"), ("jacv_entry", "jac_vals"), ("con_entry", "con"))


def lower(system, prefix: str, programs: dict, jt, memo: dict | None = None,
          data: bool = False) -> Kernels:
    """IR for ``programs`` (name -> (assignments in causal order, [(out index, expr)])
    or (those, the name of a program run first, as the Jacobian runs rhs):
    ``PROGRAMS``, and any other, e.g. an FMU's event indicators) and for the Jacobian
    from its tape ``jt`` (program ``jac`` computes the tape's partials); functions named
    ``<prefix>_<name>``, ``prefix`` an identifier. ``memo``: ``emit.programs``' (the
    symbols each expression reads), for the instance loops. ``data``: the integer tables
    (the instance loops' rows, the tape, the blocks' plans: most of a large model's IR
    as text) left out of the IR, declared external, their values in ``Kernels.data``."""
    layout = Layout(system, max(jt.n_colours, 1))
    n_eval = layout.size
    layout.pv = layout.region(max(len(jt.src), 1))
    layout.d = layout.region(jt.n_rows * jt.n_colours)
    if any(len(p) > 2 for p in programs.values()):     # a program run after another
        layout.scratch = layout.region(len(system.states))
    mod = Module(prefix, system, layout, memo, {} if data else None)
    blocks = layout.blocks.values()
    if blocks:
        mod.decls |= {MEMCPY, "declare double @llvm.fabs.f64(double)"}
        mod.functions.append(linalg.lu_ir(prefix))
    if any(b.d for b in blocks):
        mod.decls.add(MEMSET)
        mod.functions.append(linalg.assemble_ir(prefix))
    if any(b.plan is not None and b.reg < 0 for b in blocks):
        mod.functions.append(linalg.splu_ir(prefix))
    if any(b.plan is not None and b.reg >= 0 and not b.packed for b in blocks):
        mod.functions.append(linalg.splu_ir(prefix, spd=True))
    if any(b.packed for b in blocks):
        mod.functions.append(linalg.packed_ir(prefix))
    for blk in blocks:
        mod.block(blk)
    if any(b.rank >= 0 for b in blocks):
        mod.decls.add(f"declare void @{prefix}_dgesdd(i8*, i32*, i32*, double*, i32*, "
                      "double*, double*, i32*, double*, i32*, double*, i32*, i32*, i32*)")
        mod.functions.append(linalg.lstsq_ir(prefix))
    mod.tables(system.tables)
    # PROGRAMS in their order, then any other a caller asks for (an FMU's indicators)
    for name in [n for n in PROGRAMS if n in programs] + [n for n in programs
                                                          if n not in PROGRAMS]:
        mod.program(name, *programs[name])
    mod.jacobian(jt, len(system.states))
    for name, program in ENTRIES:
        if program in programs or program.startswith("jac_"):
            mod.entry(name, program, layout.size if program.startswith("jac_") else n_eval)
    n = len(system.states)
    if "out" in programs:
        mod.entry_at(n, len(programs["out"][1]), n_eval)
    n_schur = layout.size + linalg.schur_work(n, jt.n_aug) if jt.n_aug else 0
    return Kernels(mod.text(), mod.straight_text(), layout.size, n_eval, n_schur,
                   [layout.blocks[k] for k in sorted(layout.blocks)], mod.data)


def program_functions(source: str, program: str) -> list[str]:
    """The bodies of the IR functions of one program ("rhs", "jac", "out", ...) in a
    generated module's source: what a benchmark counts and a test inspects."""
    prefix = re.search(r'^_KERNEL_PREFIX = "(\w+)"', source, re.M)
    if prefix is None:
        return []
    name = re.compile(rf"{prefix.group(1)}_{program}_\d+")
    return [m.group(2) for m in re.finditer(r"^define [^@\n]*@(\w+)\(.*?\n(.*?)^}", source,
                                            re.S | re.M) if name.fullmatch(m.group(1))]

