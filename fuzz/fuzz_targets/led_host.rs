//! The host side of the LED protocol: every line a device (or line noise) could send is
//! decoded as the driver decodes it. Whatever decodes must survive a round trip through
//! the encoder.
#![no_main]

use libfuzzer_sys::fuzz_target;
use rollcam_hw::led::protocol::{decode_frame, encode_frame, parse_kv, Command, LineAssembler, LineEvent, Reply};
use rollcam_hw::led::{ChannelReadback, DeviceInfo, DeviceStatus};

fuzz_target!(|data: &[u8]| {
    let mut lines = LineAssembler::default();
    for event in lines.push(data) {
        let LineEvent::Line(line) = event else { continue };
        let Ok(frame) = decode_frame(&line) else { continue };
        // A decoded frame, encoded again, decodes to itself.
        let again = decode_frame(encode_frame(frame.seq, &frame.body).as_bytes()).expect("an encoded frame decodes");
        assert_eq!((again.seq, &again.body), (frame.seq, &frame.body));
        if let Some(reply) = Reply::parse(&frame.body) {
            if let Reply::Ack(payload) = &reply {
                let _ = parse_kv(payload);
                if let Ok(info) = DeviceInfo::from_payload(payload) {
                    let _ = info.to_payload();
                }
                if let Ok(status) = DeviceStatus::from_payload(payload) {
                    let _ = status.to_payload();
                }
                if let Ok(report) = ChannelReadback::from_payload(payload) {
                    let _ = report.to_payload();
                }
            }
            assert_eq!(Reply::parse(&reply.to_body()), Some(reply.clone()), "reply {:?}", frame.body);
        }
        // A command that parses is the same command once written out again.
        if let Ok(cmd) = Command::parse(&frame.body) {
            assert_eq!(Command::parse(&cmd.to_body()), Ok(cmd));
        }
    }
});
