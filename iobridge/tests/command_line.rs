//! iobridge's command line, as the supervisor (or a user) gives it.

#[test]
fn help_names_the_arguments_and_a_wrong_one_is_refused_by_name() {
    integration_tests::check_process_command_line(env!("CARGO_BIN_EXE_iobridge"), "iobridge");
}
