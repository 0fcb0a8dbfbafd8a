"""ROBOTIS Dynamixel Protocol 2.0 buses (the MH5's XL430 servos)."""
