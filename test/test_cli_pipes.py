"""``gripper-sim`` in a pipe whose reader has gone, or stopped by Ctrl-C: no traceback."""
import io
import subprocess
import sys

from gripper_sim.cli import main as cli_main


class ClosedPipe(io.TextIOBase):
    """A stdout whose reader has gone: every write raises BrokenPipeError."""

    def write(self, text):
        raise BrokenPipeError(32, 'Broken pipe')

    def fileno(self):
        raise io.UnsupportedOperation('not a file')


def test_a_closed_stdout_ends_the_verb_with_141_and_no_traceback(monkeypatch, capsys):
    monkeypatch.setattr(sys, 'stdout', ClosedPipe())
    assert cli_main.main(['fruits']) == cli_main.SIGPIPE_EXIT
    sys.stdout.write('later writes go nowhere\n')   # no error either
    assert 'Traceback' not in capsys.readouterr().err


def test_head_in_a_real_pipe():
    script = (f'{sys.executable} -m gripper_sim.cli.main fruits | head -1; '
              'echo "status ${PIPESTATUS[0]}" >&2')
    run = subprocess.run(['bash', '-c', script], capture_output=True, text=True, timeout=120)
    assert len(run.stdout.splitlines()) == 1
    assert 'Traceback' not in run.stderr and 'BrokenPipe' not in run.stderr, run.stderr
    assert run.stderr.strip().splitlines()[-1] in ('status 0', 'status 141'), run.stderr


def test_ctrl_c_while_the_verbs_load_ends_with_130_and_no_traceback(monkeypatch, capsys):
    def interrupted_import(name):
        raise KeyboardInterrupt
    monkeypatch.setattr(cli_main.importlib, 'import_module', interrupted_import)
    assert cli_main.main(['fruits']) == 130
    assert 'Traceback' not in capsys.readouterr().err
