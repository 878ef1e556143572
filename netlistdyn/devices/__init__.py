"""What each kind of device is: its equations and its mechanical analog."""
