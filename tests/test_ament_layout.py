"""After colcon build, every executable resolves the way `ros2 run <pkg> <exe>` resolves it
(the package prefix from the ament index, then lib/<pkg>/<exe>) and starts."""
import os
import subprocess
from pathlib import Path

import pytest
from ament_index_python.packages import get_package_prefix, get_package_share_directory

from helpers import ROOT, wait_for

# (package, executable, arguments, a line the executable logs once it runs)
EXECUTABLES = [
    ('sim_bridge', 'sim_node', [], 'with robots'),
    ('teleop', 'teleop', ['-p', 'script:=stop', '-p', 'wait_for_subscriber:=60.0'],
     'publishing on'),
    ('sim_bringup', 'drive_check', ['-p', 'script:=forward 1s'], 'waiting for'),
    ('recording', 'recorder', ['-p', 'output_dir:={tmp}'], 'recording all topics'),
    ('arm_kinematics', 'kinematics_node', ['-r', '__ns:=/youbot'], 'IK on /youbot/solve_ik'),
    ('perception', 'vision_node', [], 'looking for'),
    ('coordinator', 'coordinator_node', ['-p', 'service_timeout:=60.0'], 'real-time at'),
    ('live_view', 'live_view', ['-p', 'port:=0'], 'serving the Foxglove WebSocket protocol'),
    ('teleop', 'control_panel', ['-p', 'port:=0'], 'serving the control panel'),
]
COMMAND_LINE_TOOLS = [('recording', 'bag_analysis'), ('recording', 'bag_repair'),
                      ('studies', 'run_trials'), ('studies', 'compare_runs'),
                      ('studies', 'storyboard')]


def _ros2_run_path(package: str, executable: str) -> Path:
    # What ros2run does: get_package_prefix(package)/lib/package/executable, executable bit set.
    return Path(get_package_prefix(package)) / 'lib' / package / executable


@pytest.mark.parametrize('package, executable, args, started', EXECUTABLES,
                         ids=[e[1] for e in EXECUTABLES])
def test_executable_resolves_and_starts(tmp_path, package, executable, args, started):
    path = _ros2_run_path(package, executable)
    assert path.is_file() and os.access(path, os.X_OK), path
    assert Path(get_package_prefix(package)).is_relative_to(ROOT / 'ros_ws' / 'install')
    log = tmp_path / 'out.log'
    args = [a.replace('{tmp}', str(tmp_path)) for a in args]
    with open(log, 'w') as out:
        proc = subprocess.Popen([str(path), '--ros-args'] + args, stdout=out,
                                stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
        try:
            wait_for(lambda: started in log.read_text() or proc.poll() is not None, 20.0,
                     what=f'{executable} to start')
            assert proc.poll() is None, log.read_text()
        finally:
            proc.send_signal(2)
            proc.wait(10)


@pytest.mark.parametrize('package, executable', COMMAND_LINE_TOOLS,
                         ids=[e[1] for e in COMMAND_LINE_TOOLS])
def test_command_line_tool_resolves_and_runs(package, executable):
    path = _ros2_run_path(package, executable)
    assert path.is_file() and os.access(path, os.X_OK), path
    out = subprocess.run([str(path), '--help'], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0 and f'usage: {executable}' in out.stdout


def test_every_package_is_in_the_ament_index():
    for package in ('sim_bridge', 'controllers', 'perception', 'robot_description',
                    'sim_bringup', 'sim_interfaces', 'recording', 'arm_kinematics',
                    'coordinator', 'cell_layout', 'trial_record', 'studies', 'ros_common',
                    'world_description', 'teleop', 'live_view'):
        share = Path(get_package_share_directory(package))
        assert (share / 'package.xml').is_file()
    assert (Path(get_package_share_directory('robot_description')) / 'urdf' /
            'mini_robot.urdf').is_file()
    assert (Path(get_package_share_directory('live_view')) / 'layouts' /
            'pipeline_cell.json').is_file()
    for world in ('mini_robot', 'youbot', 'pipeline_cell'):
        assert (Path(get_package_share_directory('world_description')) / 'worlds' /
                f'{world}.yaml').is_file()
    for robot in ('youbot', 'zu12'):
        assert (Path(get_package_share_directory('robot_description')) / 'urdf' /
                f'{robot}.urdf').is_file()
    for executable in ('arm_move', 'drive_check'):
        assert _ros2_run_path('sim_bringup', executable).is_file()


def test_interface_package_generated_python_bindings():
    from sim_interfaces.msg import MaterialDetection, MaterialDetectionArray
    assert MaterialDetectionArray(detections=[MaterialDetection(id=3)]).detections[0].id == 3
    from sim_interfaces.srv import SolveIK, StepSimulation
    assert StepSimulation.Request(steps=3).steps == 3
    assert SolveIK.Request(execute=True).execute
    fields = StepSimulation.Response.get_fields_and_field_types()
    assert fields == {'success': 'boolean', 'message': 'string', 'commands_pending': 'boolean',
                      'step_count': 'uint64', 'sim_time': 'builtin_interfaces/Time'}


def test_launch_file_is_valid_python_for_a_full_install():
    launch = Path(get_package_share_directory('sim_bringup')) / 'launch'
    files = sorted(launch.glob('*.launch.py'))
    assert files
    for f in files:
        compile(f.read_text(), str(f), 'exec')
