"""Object databases: the .dat format of the SNO manipulator (VERSION1.00, TYPE: name ... END;), read and written back atomically."""
