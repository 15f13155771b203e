"""``bench faults`` in parts (processes, figures, text): the command line
still finds what it uses in ``telethermal.bench.faults``."""

from telethermal.bench import faults, faults_plot, faults_procs, faults_sim, faults_text


def test_the_facade_exports_what_the_command_line_uses():
    assert faults.run.__module__ == "telethermal.bench.faults"
    assert faults.plot is faults_plot.plot
    assert faults.text_report is faults_text.text_report
    assert faults.SETTINGS is faults_procs.SETTINGS
    assert faults.SETTINGS[0][0] == "delay 0 ms" == faults_sim.ROWS[0][0]


def test_the_processes_rows_keep_their_names_and_order():
    # Names are keys of the JSON (rows' "fault", the summary's settings).
    assert [name for name, _ in faults.SETTINGS] == [
        "delay 0 ms", "delay 200 ms", "delay 200 ms, jitter 20 ms, loss 5 %", "loss 20 %",
        "2 s partition mid-contact", "slave crash and restart mid-contact",
        "master crash and restart mid-contact"]
