"""A refused value changes nothing, through the built FMUs in an fmpy host.

A tunable parameter set during the run is checked by every rule of its controller; one the rules refuse is
fmi2Error, the variable reads back its old value and the instance steps on as if the set had never been made.
The property (tests/fmi/refused_sets_host.py) runs for every FMU in a process of its own, so a crash is a failure.
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Slave

from ncfmu.catalogue import models

HOST = Path(__file__).with_name("refused_sets_host.py")
DT = 1e-3


def test_a_refused_repeat_period_reads_back_the_old_one_and_presses_nothing(fmus, tmp_path):
    """The reported case: OperatorPanel's fmi2SetReal(repeat_every = 5e-324) during the run is refused; the
    variable reads -1 and the next step presses neither START nor EMB (pushed at 0 s, released after 10 ms)."""
    md = read_model_description(str(fmus["OperatorPanel"]))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    panel = FMU2Slave(guid=md.guid, unzipDirectory=extract(str(fmus["OperatorPanel"]), str(tmp_path)),
                      modelIdentifier="OperatorPanel", instanceName="panel")
    panel.instantiate()
    try:
        panel.setupExperiment(startTime=0.0)
        panel.enterInitializationMode()
        panel.setReal([vr["start_at"], vr["emergency_at"]], [0.0, 0.0])
        panel.exitInitializationMode()
        for k in range(20):
            panel.doStep(k * DT, DT)
        with pytest.raises(FMICallException) as refused:
            panel.setReal([vr["repeat_every"]], [5e-324])
        assert refused.value.status == 3                                     # fmi2Error
        assert panel.getReal([vr["repeat_every"]]) == [-1.0]
        panel.doStep(20 * DT, DT)
        assert panel.getBoolean([vr["start"], vr["emergency"]]) == [False, False]
        # the panel still takes a period its rules allow: the buttons press again at 0 s of each period
        panel.setReal([vr["repeat_every"]], [0.015])
        panel.doStep(21 * DT, DT)                                             # 22 ms: 7 ms into the 2nd period
        assert panel.getBoolean([vr["start"], vr["emergency"]]) == [True, True]
    finally:
        panel.terminate()
        panel.freeInstance()


@pytest.mark.slow                                      # a process per FMU, 60 examples of 120 steps of two twins
@pytest.mark.parametrize("model", sorted(models()))
def test_a_refused_set_leaves_the_instance_as_its_twin(fmus, model):
    proc = subprocess.run([sys.executable, str(HOST), str(fmus[model]), "60"], capture_output=True, text=True,
                          timeout=600)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    examples, offers, refused = map(int, re.search(r"^EXAMPLES (\d+) OFFERS (\d+) REFUSED (\d+)$", proc.stdout,
                                                   re.MULTILINE).groups())
    print(f"{model}: {examples} examples, {offers} values offered, {refused} refused")
    assert examples >= 60 and refused >= offers // 4          # the property is about refused values: many are
