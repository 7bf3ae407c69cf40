# bgc: the README's two commands are `make run` and `make test`.
PYTHON ?= python3
# the main job's settings, and why: docs/main-job.md
SARIB = bgc simulate models/sarib.yaml --excitation chirp --no-states --solver native --method zcp --rtol 1e-4 --atol 1e-4

.PHONY: install run demo semiactive test test-all bench generated clean

install:
	$(PYTHON) -m pip install -q -e ".[test]"

# The main job: the SARIB suspension under the paper's pumping chirp (5 -> 25 Hz over
# 5..25 s, 28 s in all): CSV of the outputs, their time histories, their envelopes against
# the instantaneous frequency (the anti-resonance), a zoom on 17.8..18.2 s, and the HTML
# report (bgc report: zoomable plots, FRF, modes, the mechanism in 3D) beside them.
run: install
	$(SARIB) --direction pumping --out results/sarib_pumping_chirp.csv \
	    --plot results/sarib_pumping_chirp.png --zoom 17.8 18.2 \
	    --report results/sarib_pumping_chirp.html

# The other two directions of the paper's cases (roll: the phase shift of F_A1_z and F_A2_z).
demo: run
	$(SARIB) --direction roll --out results/sarib_roll_chirp.csv \
	    --plot results/sarib_roll_chirp.png --zoom 17.8 18.2 \
	    --report results/sarib_roll_chirp.html
	$(SARIB) --direction pitch --out results/sarib_pitch_chirp.csv \
	    --plot results/sarib_pitch_chirp.png --zoom 17.8 18.2 \
	    --report results/sarib_pitch_chirp.html

# The semi-active SARIB (issue 26): its anti-resonance against the flapping masses'
# setpoint under each method, and the absorber retuning to a rotor-frequency step: CSV,
# PNG and summary.md in results/semiactive (a few minutes).
semiactive: install
	$(PYTHON) -m bgc.bench.semiactive --out results/semiactive

# Fast suite (slow SARIB runs are marked `slow` and left to test-all).
test:
	$(PYTHON) -m pytest -q -n 2 --dist worksteal

test-all:
	$(PYTHON) -m pytest -q -n 2 -m ""

# Speed against accuracy (issue 6): peers, work-precision, parasitic stiffness, stability
# maps, compile cost, an assembly's compile cost (--part components); CSV + PNG +
# summary.md in bench/results (an hour or more; --quick: minutes).
bench: install
	bgc bench --results bench/results

# Regenerate the committed modules in generated/ (a test checks they are fresh).
generated:
	for m in models/*.yaml; do bgc compile $$m -o generated || exit 1; done

clean:
	rm -rf results .pytest_cache generated/__pycache__
