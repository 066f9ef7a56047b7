"""`ros2_control_node`: the controller manager node (controller_manager_py.ros.node).

    ros2_control_node --ros-args --params-file config/ur_controllers.yaml \
        -p robot_description_file:=config/mock_ur.urdf
"""
from .ros.node import ControllerManagerNode
from .ros.node_main import main_for

main = main_for(ControllerManagerNode)

if __name__ == "__main__":
    main()
