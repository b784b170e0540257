"""The container image's recipe (docker/Dockerfile): what `make container-test` builds and runs
(minutes, so not part of `make test`), checked here for the promises a change could break
without anyone building the image: the base is an argument, the wheels are installed in a layer
before the code, the default command is the demo, the build context leaves out what the host
built."""
import re
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _instructions():
    text = (ROOT / 'docker' / 'Dockerfile').read_text()
    text = re.sub(r'\\\n', ' ', text)
    return [line.split(None, 1) for line in text.splitlines()
            if line.strip() and not line.lstrip().startswith('#')]


def test_the_base_image_is_a_build_argument_with_a_debian_or_ubuntu_default():
    steps = _instructions()
    assert steps[0][0] == 'ARG' and steps[0][1].startswith('BASE=')
    assert re.search(r'(debian|ubuntu):', steps[0][1])
    assert steps[1] == ['FROM', '${BASE}']


def test_the_wheels_are_installed_before_the_code_is_copied_in():
    steps = [' '.join(s) for s in _instructions()]
    venv = next(i for i, s in enumerate(steps) if 'setup.sh --venv-only' in s)
    code = steps.index('COPY . .')
    copied_before = [s for s in steps[:venv] if s.startswith('COPY ')]
    assert venv < code and steps[code + 1] == 'RUN bash scripts/setup.sh'
    # only what the virtualenv stage reads: the lock files and the setup scripts
    assert copied_before == ['COPY requirements/ requirements/',
                             'COPY scripts/setup.sh scripts/fix_wheel_cmake_paths.py scripts/']
    assert steps[-1] == 'CMD ["make", "demo"]'


def test_a_ca_certificate_can_be_handed_to_the_build():
    steps = [' '.join(s) for s in _instructions()]
    assert 'ARG EXTRA_CA_CERT=""' in steps
    install = next(s for s in steps if 'apt-get install' in s)
    assert 'EXTRA_CA_CERT' in install and 'update-ca-certificates' in install


def test_the_build_context_leaves_out_what_the_host_built():
    ignored = {line.strip() for line in (ROOT / '.dockerignore').read_text().splitlines()}
    assert {'.git', '.venv', 'ros_ws/build', 'ros_ws/install', 'ros_ws/log', 'runs'} <= ignored


def test_setup_refuses_an_unknown_argument():
    out = subprocess.run(['bash', str(ROOT / 'scripts' / 'setup.sh'), '--venv-onyl'],
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 2 and 'unknown argument --venv-onyl' in out.stderr
