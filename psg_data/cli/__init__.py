"""psg_data.cli"""
