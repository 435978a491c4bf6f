//! Commands that need no device: `crc`, help, hex input errors.

use crate::server::{offline, stderr, stdout};

#[test]
fn crc_of_the_sdp_request_is_fc_eb() {
    let out = stdout(&offline(&["crc", "01 10 01 12 00 02 04 0B B8 00 00"]).success());
    assert_eq!(
        out,
        "CRC-16/MODBUS  0xEBFC\n\
         wire bytes     FC EB  (low byte first)\n\
         RTU frame      01 10 01 12 00 02 04 0B B8 00 00 FC EB\n\
         LRC            0x13\n\
         ASCII frame    :011001120002040BB8000013\\r\\n\n"
    );
}

#[test]
fn crc_of_the_sdp_reply_is_e0_31_and_the_input_may_be_split_anyhow() {
    let want = "CRC-16/MODBUS  0x31E0\n\
                wire bytes     E0 31  (low byte first)\n\
                RTU frame      01 10 01 12 00 02 E0 31\n\
                LRC            0xDA\n\
                ASCII frame    :011001120002DA\\r\\n\n";
    assert_eq!(stdout(&offline(&["crc", "01", "10", "01", "12", "00", "02"]).success()), want);
    assert_eq!(stdout(&offline(&["crc", "011001", "120002"]).success()), want);
    assert_eq!(stdout(&offline(&["crc", "0x01,0x10,0x01,0x12,0x00,0x02"]).success()), want);
}

#[test]
fn crc_check_accepts_a_good_frame_and_names_the_right_crc_for_a_bad_one() {
    let good = offline(&["crc", "--check", "01 10 01 12 00 02 E0 31"]).success();
    assert_eq!(stdout(&good), "CRC OK: E0 31 (0x31E0)\n");
    // The byte order vendor manuals get wrong: 31 E0 is the CRC with its bytes swapped.
    let bad = offline(&["crc", "--check", "01 10 01 12 00 02 31 E0"]).code(5);
    let err = stderr(&bad);
    assert!(err.contains("ends with 31 E0, expected E0 31"), "{err}");
    assert!(err.contains("01 10 01 12 00 02 E0 31"), "{err}");
    offline(&["crc", "--check", "E0 31"]).code(2);
}

#[test]
fn hex_errors_say_where_the_problem_is() {
    let odd = offline(&["crc", "01", "100"]).code(2);
    assert!(
        stderr(&odd).contains("'100' (argument 2, character 1) has an odd number of hex digits"),
        "{}",
        stderr(&odd)
    );
    let bad = offline(&["crc", "01 1G"]).code(2);
    assert!(stderr(&bad).contains("'G' (argument 1, character 5) is not a hex digit"), "{}", stderr(&bad));
    offline(&["crc", ","]).code(2);
}

#[test]
fn help_explains_addresses_and_exit_codes() {
    let out = stdout(&offline(&["--help"]).success());
    assert!(out.contains("ADDRESS is the wire address (0-based, as on the bus); use --one-based"), "{out}");
    assert!(out.contains("Exit codes:"));
    for code in [
        "0  success",
        "1  the device answered with an exception",
        "2  usage error",
        "3  timeout",
        "4  IO error",
        "5  bad reply",
        "6  output error",
        "130  interrupted",
        "141  stdout closed by its reader",
    ] {
        assert!(out.contains(code), "{code}");
    }
    assert!(out.contains("--modicon for a Modicon reference like 40001"), "{out}");
    let read = stdout(&offline(&["read", "--help"]).success());
    assert!(read.contains("--modicon for a Modicon reference like 40001"), "{read}");
    assert!(read.contains("--modicon"), "{read}");
}
