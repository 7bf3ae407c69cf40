"""Run FMUs with fmpy alone, as an importing tool would: validated, simulated as Model
Exchange (fmpy's CVode) and as Co-Simulation (a master stepping at 1 ms), and the
Jacobian read through fmi2GetDirectionalDerivative at the start. Started by the tests as
a separate process that never imports bgc; prints one JSON object.

    python run_fmpy.py JOBS_JSON

JOBS_JSON: a list of {"fmu", "t_end", "rtol_me", "rtol_cs", "start": {name: value},
"input": {name: constant value}}."""

import json
import sys

import numpy as np
from fmpy import extract, read_model_description, simulate_fmu
from fmpy.fmi2 import FMU2Model
from fmpy.validation import validate_fmu


def jacobian(path, start):
    """d der(x) / dx at the start, column by column through the directional derivative."""
    md = read_model_description(path)
    fmu = FMU2Model(guid=md.guid, unzipDirectory=extract(path),
                    modelIdentifier=md.modelExchange.modelIdentifier, instanceName="jac")
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    for name, value in start.items():
        vr = next(v.valueReference for v in md.modelVariables if v.name == name)
        fmu.setReal([vr], [value])
    fmu.exitInitializationMode()
    states = [v.valueReference for v in md.modelVariables if v.derivative is None
              and v.causality == "local" and not v.name.startswith("der(")]
    ders = [v.valueReference for v in md.modelVariables if v.derivative is not None]
    x = fmu.getReal(states)
    cols = [fmu.getDirectionalDerivative(ders, [s], [1.0]) for s in states]
    fmu.terminate()
    fmu.freeInstance()
    return np.array(cols).T.tolist(), x


def main():
    out = []
    for job in json.loads(sys.argv[1]):
        path, start = job["fmu"], job.get("start", {})
        signals = None
        if job.get("input"):
            names = list(job["input"])
            signals = np.array([(t, *job["input"].values()) for t in (0.0, job["t_end"])],
                               dtype=[("time", np.float64)] + [(n, np.float64) for n in names])
        res = {"problems": validate_fmu(path)}
        md = read_model_description(path)
        for kind, rtol in (("ModelExchange", job["rtol_me"]), ("CoSimulation", job["rtol_cs"])):
            if kind == "ModelExchange" and md.modelExchange is None:
                continue
            r = simulate_fmu(path, fmi_type=kind, stop_time=job["t_end"],
                             output_interval=1e-3, relative_tolerance=rtol,
                             start_values=start, input=signals)
            res[kind] = {n: r[n].tolist() for n in r.dtype.names}
        if md.modelExchange is not None:
            res["jacobian"], res["x0"] = jacobian(path, start)
        out.append(res)
    print(json.dumps({"results": out, "bgc_imported": "bgc" in sys.modules}))


if __name__ == "__main__":
    main()
