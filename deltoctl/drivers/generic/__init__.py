"""Profiles with no hardware protocol: ros2_control's mock_components/GenericSystem."""
